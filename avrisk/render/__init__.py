"""Camera images of the simulated scene, for vision egos.

* :mod:`~avrisk.render.rays` -- :class:`CameraModel`: a pinhole camera's
  intrinsics and its mount on the ego, one ray per pixel;
* :mod:`~avrisk.render.raycast` -- :class:`RayCastCamera`: the ego's RGB,
  depth and semantic segmentation for a whole batch of rollouts at once, by
  casting every pixel's ray against the road plane and the vehicle boxes.

It implements the simulator's camera seam (:mod:`avrisk.sim.camera`) and
builds on :mod:`avrisk.sim` only; :mod:`avrisk.assembly` hands a camera to the
simulator when a scenario's ego reads one.
"""

from avrisk.render.raycast import (
    DEFAULT_VEHICLE_HEIGHT,
    PALETTE,
    RayCastCamera,
    RoadPaint,
)
from avrisk.render.rays import CameraModel, PixelRays

__all__ = [
    "DEFAULT_VEHICLE_HEIGHT",
    "PALETTE",
    "CameraModel",
    "PixelRays",
    "RayCastCamera",
    "RoadPaint",
]
