"""Real satellite geometry: pushbroom scenes from RPCs (space resection, the papers' pipeline)
and rigorous line-scan models from vendor metadata (Pleiades DIMAP v1.4, DigitalGlobe XML).

See ``docs/real_images.md``; conventions in ``docs/conventions.md``.
"""

from explorer.real.compare import RPCComparison, compare_with_rpc
from explorer.real.from_rpc import scene_from_rpc
from explorer.real.linescan import RigorousLineScanScene, load_scene
from explorer.real.resection import ResectionReport, mpc_from_lines_of_sight, project_to_image, resect

__all__ = [
    "RPCComparison",
    "ResectionReport",
    "RigorousLineScanScene",
    "compare_with_rpc",
    "load_scene",
    "mpc_from_lines_of_sight",
    "project_to_image",
    "resect",
    "scene_from_rpc",
]
