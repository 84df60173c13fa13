"""Data files shipped with the package (presets, DEM samples, the EGM96 grid).

The checkout's ``assets/`` folder is the one source of truth: the build maps it to the sub-package
``explorer.assets`` (``package-dir`` in ``setup.py``), so an editable install and an installed wheel both
find the same files through :mod:`importlib.resources`, never through a path beside the package.
"""

from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable
from pathlib import Path

from explorer.errors import SceneFileError

ASSETS_PACKAGE = "explorer.assets"


def asset(*parts: str) -> Traversable:
    """Return the packaged data file ``assets/<parts...>`` as a :class:`~importlib.abc.Traversable`.

    Raises
    ------
    SceneFileError
        If the package was imported without its data (a source tree that was never installed) or the file
        is not among the package data.
    """
    try:
        root = resources.files(ASSETS_PACKAGE)
    except ModuleNotFoundError as exc:
        raise SceneFileError(
            "the package data (explorer.assets) is not installed: install the package "
            "(`pip install -e .` in the checkout, or the wheel) instead of importing it from a bare source tree"
        ) from exc
    node = root.joinpath(*parts)
    if not node.is_file():
        raise SceneFileError(f"packaged data file assets/{'/'.join(parts)} is missing from the installation")
    return node


def asset_path(*parts: str) -> Path:
    """Return a filesystem path to the packaged data file ``assets/<parts...>``.

    Installed packages (wheel or editable) live on the filesystem, so the traversable is a real path; this is
    what GDAL/rasterio and ``numpy.fromfile`` need.

    Raises
    ------
    SceneFileError
        As :func:`asset`, or if the package is imported from a zip archive.
    """
    node = asset(*parts)
    path = Path(str(node))
    if not path.is_file():
        raise SceneFileError(f"packaged data file assets/{'/'.join(parts)} is not on the filesystem ({node})")
    return path


def assets_dir(*parts: str) -> Path:
    """Return the filesystem folder of the packaged data ``assets/<parts...>`` (e.g. ``"dem"``)."""
    try:
        root = resources.files(ASSETS_PACKAGE)
    except ModuleNotFoundError as exc:
        raise SceneFileError("the package data (explorer.assets) is not installed") from exc
    return Path(str(root.joinpath(*parts)))
