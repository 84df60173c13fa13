"""A module imported on first attribute access (torch costs ~2 s to import; most runs of the CLI, the
model layer and the compiled methods never touch it)."""

from __future__ import annotations

import importlib
import types


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
