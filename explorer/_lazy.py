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
