"""The explorer's 3D scene: viser builders for pushbroom geometry (``builders``).

Display frame and the compressed sensor distance: ``docs/explorer.md``.
"""

from explorer.scene3d.builders import DisplayFrame

__all__ = ["DisplayFrame"]
