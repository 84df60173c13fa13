"""pushbroom-explorer: object-to-image transformation of linear pushbroom satellite images.

The model layer (``explorer.geometry``, ``explorer.scene``, ``explorer.points``,
``explorer.methods``, ``explorer.rpc``) depends only on numpy, scipy and torch; the
3D scene (``explorer.scene3d``) and the Plotly panels (``explorer.panels``) only read
its results.  Conventions (pixel centre, row <-> time, frames, rotation order) are
written once in ``docs/conventions.md``.
"""

from explorer.errors import ConvergenceError, InputError, SceneFileError

__version__ = "0.1.0"

__all__ = ["ConvergenceError", "InputError", "SceneFileError", "__version__"]
