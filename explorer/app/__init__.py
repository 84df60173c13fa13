"""The pushbroom explorer: a viser 3D scene of the imaging geometry with Plotly residual panels,
driven by the method registry.

The package splits the explorer in layers (``docs/explorer.md``; architecture:
``docs/dev/architecture.md``):

* :mod:`explorer.app.model` -- :class:`ExplorerModel` (state and computation, cached; no viser,
  no plotly) and :class:`Settings`;
* :mod:`explorer.sources` -- the one source shown (preset, scene JSON, RPC, DIMAP, DG,
  CSM ISD) resolved and validated before a server starts;
* :mod:`explorer.app.export` -- ``summary.json``, ``residuals.csv``, ``panels.html``;
* :mod:`explorer.app.jobs` -- :class:`FitPool`, the background training threads;
* :mod:`explorer.app.gui`, :mod:`explorer.app.controls`, :mod:`explorer.app.views` --
  :class:`ExplorerApp`: the controls, the worker thread and the drawing;
* :mod:`explorer.app.server` -- :func:`serve` and ``pushbroom explore``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from explorer._lazy import lazy_names

if TYPE_CHECKING:
    from explorer.app.gui import DEBOUNCE_S, ExplorerApp
    from explorer.app.jobs import FitPool
    from explorer.app.model import (
        COLOUR_LIMITS_PX,
        COLOUR_MODES,
        COMPONENTS,
        DEFAULT_METHODS,
        PARAM_ALIASES,
        SCOP_DENSITIES,
        SCP_COUNTS,
        STATUS_NAMES,
        ExplorerModel,
        FitRecord,
        MethodRun,
        Selection,
        Settings,
        accepted_params,
        control_default,
        gui_params,
        safe_available,
        summary_markdown,
    )
    from explorer.app.server import check_listen_address, serve
    from explorer.app.views import Superseded

#: public name -> the submodule defining it.  The names are imported on first access (PEP 562), not with the
#: package: ``import explorer.app.model`` (the export's sweep worker, :mod:`explorer.app.sweep_pool`) then
#: imports the model alone, not the GUI's modules (gui, controls, views, server, jobs) it never uses.
_SOURCES = {
    **dict.fromkeys(("DEBOUNCE_S", "ExplorerApp"), "explorer.app.gui"),
    "FitPool": "explorer.app.jobs",
    **dict.fromkeys(("COLOUR_LIMITS_PX", "COLOUR_MODES", "COMPONENTS", "DEFAULT_METHODS", "PARAM_ALIASES",
                     "SCOP_DENSITIES", "SCP_COUNTS", "STATUS_NAMES", "ExplorerModel", "FitRecord", "MethodRun",
                     "Selection", "Settings", "accepted_params", "control_default", "gui_params", "safe_available",
                     "summary_markdown"), "explorer.app.model"),
    **dict.fromkeys(("check_listen_address", "serve"), "explorer.app.server"),
    "Superseded": "explorer.app.views",
}


__getattr__, __dir__ = lazy_names(globals(), _SOURCES)


__all__ = [
    "COLOUR_LIMITS_PX", "COLOUR_MODES", "COMPONENTS", "DEBOUNCE_S", "DEFAULT_METHODS", "PARAM_ALIASES",
    "SCOP_DENSITIES", "SCP_COUNTS", "STATUS_NAMES", "ExplorerApp", "ExplorerModel", "FitPool", "FitRecord",
    "MethodRun", "Selection", "Settings", "Superseded", "accepted_params", "check_listen_address",
    "control_default", "gui_params", "safe_available", "serve", "summary_markdown",
]
