"""Best scanline search / determination methods behind one interface.

``available()`` lists them, ``create(name, scene, **params)`` builds one; every
module in this package that defines a registered class is discovered
automatically, so adding a method is one new module (plus its tests).
"""

from __future__ import annotations

from explorer.methods.base import (
    DISCOVERY_ERRORS,
    BestScanlineMethod,
    ScanlineResult,
    available,
    create,
    discover,
    register,
    registry,
    unavailable_reason,
)

__all__ = [
    "DISCOVERY_ERRORS", "BestScanlineMethod", "ScanlineResult", "available", "create", "discover", "register",
    "registry", "unavailable_reason",
]
