"""Best scanline search / determination methods behind one interface.

``available()`` lists them, ``create(name, scene, **params)`` builds one; every
module in this package that defines a registered class is discovered
automatically, so adding a method is one new module (plus its tests).
"""

from __future__ import annotations

import importlib
import pkgutil
import warnings

from explorer.methods.base import (
    BestScanlineMethod,
    ScanlineResult,
    available,
    create,
    register,
    registry,
)

_DISCOVERED = False
DISCOVERY_ERRORS: dict[str, str] = {}


def discover() -> None:
    """Import every module of this package once so their ``@register`` decorators run.

    A module that fails to import does not hide the others: its error is kept in
    :data:`DISCOVERY_ERRORS` and reported with a warning (the test suite asserts there is none).
    """
    global _DISCOVERED
    if _DISCOVERED:
        return
    for mod in pkgutil.iter_modules(__path__):
        if mod.name in ("base",) or mod.name.startswith("_"):
            continue
        try:
            importlib.import_module(f"{__name__}.{mod.name}")
        except Exception as exc:  # noqa: BLE001 - reported, never swallowed silently
            DISCOVERY_ERRORS[mod.name] = f"{type(exc).__name__}: {exc}"
            warnings.warn(f"method module {mod.name!r} failed to import: {exc}", RuntimeWarning, stacklevel=2)
    _DISCOVERED = True


__all__ = [
    "DISCOVERY_ERRORS", "BestScanlineMethod", "ScanlineResult", "available", "create", "discover", "register",
    "registry",
]
