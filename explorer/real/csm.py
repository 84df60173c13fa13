"""USGS Community Sensor Model line-scan cameras: the public API.

* :func:`read_isd` -- a line-scan ISD (JSON written by USGS ALE) -> :class:`CsmCamera` with compiled
  ``image_to_ground(line, sample, height)`` / ``ground_to_image(xyz)`` in usgscsm's conventions
  (:mod:`explorer.real.csm_camera`, kernels in :mod:`explorer.real.csm_kernels`);
* :func:`scene_from_isd` -- the same camera as the project's :class:`~explorer.scene.Scene`, for every
  method, the bench and the explorer (:mod:`explorer.real.csm_scene`).

Conventions: ``docs/conventions.md#usgs-csm-line-scan-isds``; measured numbers: ``docs/real_images.md``.
"""

from explorer.real.csm_camera import (
    SUPPORTED_DISTORTIONS,
    CsmCamera,
    GroundToImage,
    ImageToGround,
    camera_from_isd,
    read_isd,
)
from explorer.real.csm_scene import body_fixed_to_enu, enu_to_body_fixed, scene_from_camera, scene_from_isd

__all__ = [
    "SUPPORTED_DISTORTIONS", "CsmCamera", "GroundToImage", "ImageToGround", "body_fixed_to_enu", "camera_from_isd",
    "enu_to_body_fixed", "read_isd", "scene_from_camera", "scene_from_isd",
]
