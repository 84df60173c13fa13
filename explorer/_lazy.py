"""A module imported on first attribute access (torch costs ~2 s to import; most runs of the CLI, the
model layer and the compiled methods never touch it)."""

from __future__ import annotations

import importlib
import types
from collections.abc import Callable
from typing import Any


class LazyModule(types.ModuleType):
    """Stands for the module ``name`` and imports it when an attribute is first read.

    Parameters
    ----------
    name : str
        Importable module name, e.g. ``"torch"``.
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)

    def __getattr__(self, attr: str):
        module = importlib.import_module(self.__name__)
        self.__dict__.update(module.__dict__)  # later lookups skip this method
        return getattr(module, attr)


def import_rasterio() -> types.ModuleType:
    """``import rasterio`` without importing boto3 (the AWS SDK, ~40 % of rasterio's import time).

    rasterio's ``session`` module imports boto3 when it is installed, for ``s3://`` datasets; the package only
    opens local files (its raster arguments must exist).  Unless rasterio or boto3 is already imported,
    rasterio is imported while ``import boto3`` fails (``sys.modules["boto3"] = None``), which rasterio handles
    as boto3 not being installed; ``import boto3`` elsewhere works as before afterwards.
    """
    import sys

    if "rasterio" in sys.modules or "boto3" in sys.modules:
        return importlib.import_module("rasterio")
    sys.modules["boto3"] = None  # type: ignore[assignment]
    try:
        return importlib.import_module("rasterio")
    finally:
        if sys.modules.get("boto3", 0) is None:
            del sys.modules["boto3"]


def lazy_names(namespace: dict, sources: dict[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` (PEP 562) of a package whose public names are imported on first
    access: ``sources`` maps each name to the module defining it; a name read once is cached in ``namespace``
    (the package's ``globals()``), so later lookups skip ``__getattr__``.

    Use: ``__getattr__, __dir__ = lazy_names(globals(), _LAZY)``.
    """
    package = namespace["__name__"]

    def __getattr__(name: str) -> Any:  # noqa: N807 - the module hook's own name
        source = sources.get(name)
        if source is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(source), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:  # noqa: N807
        return sorted(set(namespace) | set(sources))

    return __getattr__, __dir__
