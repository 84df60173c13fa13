"""Best scanline search / determination methods behind one interface.

``available()`` lists them, ``create(name, scene, **params)`` builds one; every
module in this package that defines a registered class is discovered
automatically, so adding a method is one new module (plus its tests).
"""

from __future__ import annotations

import importlib
import pkgutil

from explorer.methods.base import (
    BestScanlineMethod,
    ScanlineResult,
    available,
    create,
    register,
    registry,
)

_DISCOVERED = False


def discover() -> None:
    """Import every module of this package once so their ``@register`` decorators run."""
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    for mod in pkgutil.iter_modules(__path__):
        if mod.name not in ("base",) and not mod.name.startswith("_"):
            importlib.import_module(f"{__name__}.{mod.name}")


__all__ = ["BestScanlineMethod", "ScanlineResult", "available", "create", "discover", "register", "registry"]
