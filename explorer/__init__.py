"""pushbroom-explorer: object-to-image transformation of linear pushbroom satellite images.

The names a notebook or script needs are importable from here (``from explorer import build_scene``);
they are imported on first use (module ``__getattr__``), so ``import explorer`` stays fast and the
command line starts without numpy-heavy imports.  Layers and the one direction of imports:
``docs/dev/architecture.md``; conventions (pixel centre, row <-> time, frames, rotation order):
``docs/conventions.md``.

=====================  ==================================================================
scenes                 :class:`Scene`, :func:`build_scene`, :func:`preset_ids`,
                       :func:`default_preset_id`, :func:`load_scene`, :class:`Sensor`,
                       :class:`LocalFrame`
points                 :func:`simulate_points`, :func:`image_grid`, :class:`PointSet`
methods                :func:`available`, :func:`create`, :func:`registry`,
                       :class:`BestScanlineMethod`, :class:`ScanlineResult`
evaluation             :func:`evaluate_method`, :class:`Evaluation`, :func:`run_bench`
RPC models             :func:`read_rpc`, :class:`RationalFunctionModel`, :class:`RPCSensor`
real images            :func:`scene_from_rpc`, :func:`mpc_scene_from_sensor`,
                       :class:`RigorousLineScanScene`
errors                 :class:`InputError`, :class:`SceneFileError`, :class:`ConvergenceError`
=====================  ==================================================================
"""

from __future__ import annotations

from explorer._lazy import lazy_names
from explorer.errors import ConvergenceError, InputError, SceneFileError

__version__ = "0.1.0"

#: Public name -> module that defines it (imported on first access).
_LAZY: dict[str, str] = {
    "Scene": "explorer.scene",
    "Sensor": "explorer.sensor",
    "LocalFrame": "explorer.geometry.frames",
    "build_scene": "explorer.presets",
    "preset_ids": "explorer.presets",
    "default_preset_id": "explorer.presets",
    "load_scene": "explorer.real.linescan",
    "PointSet": "explorer.points",
    "image_grid": "explorer.points",
    "simulate_points": "explorer.points",
    "available": "explorer.methods",
    "create": "explorer.methods",
    "registry": "explorer.methods",
    "BestScanlineMethod": "explorer.methods",
    "ScanlineResult": "explorer.methods",
    "Evaluation": "explorer.evaluate",
    "evaluate_method": "explorer.evaluate",
    "run_bench": "explorer.bench",
    "RationalFunctionModel": "explorer.rpc",
    "read_rpc": "explorer.rpc",
    "RPCSensor": "explorer.rpc.sensor",
    "scene_from_rpc": "explorer.real.from_rpc",
    "mpc_scene_from_sensor": "explorer.real.mpc_fit",
    "RigorousLineScanScene": "explorer.real.linescan",
}


__getattr__, __dir__ = lazy_names(globals(), _LAZY)


__all__ = ["ConvergenceError", "InputError", "SceneFileError", "__version__", *sorted(_LAZY)]
