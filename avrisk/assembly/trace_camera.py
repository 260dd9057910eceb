"""The ego camera's images of a recorded rollout, rendered again from its trace.

For a scenario whose ego has a camera, :func:`camera_frames` renders what the
ego saw at every recorded step (every vehicle's pose at that step), with the
scenario's own camera: the same ray caster as in the rollout, so the same
pixels, and neither the ego nor any code a spec names is needed. The report
shows them beside the top-down view (:mod:`avrisk.report.camera_video`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.assembly.traces import RolloutTrace
from avrisk.sim.camera import Camera, SemanticClass
from avrisk.sim.state import VehicleState

__all__ = ["SEGMENT_CLASSES", "CameraFrames", "camera_frames"]

#: Name of each segmentation class, indexed by its label (``SemanticClass``).
SEGMENT_CLASSES: tuple[str, ...] = tuple(
    c.name.lower().replace("_", " ") for c in sorted(SemanticClass)
)


class CameraFrames(NamedTuple):
    """The ego camera's images at each recorded step of one rollout.

    Attributes
    ----------
    rgb : ndarray of shape (T, H, W, 3)
        Colour in ``[0, 1]``.
    depth : ndarray of shape (T, H, W)
        Distance along the optical axis [m]; ``inf`` for sky.
    segmentation : ndarray of int8, shape (T, H, W)
        Label of each pixel (:data:`SEGMENT_CLASSES` names them).
    """

    rgb: NDArray[np.float32]
    depth: NDArray[np.float32]
    segmentation: NDArray[np.int8]


def camera_frames(trace: RolloutTrace, camera: Camera) -> CameraFrames:
    """Render the ego camera at every recorded step of ``trace``.

    Parameters
    ----------
    trace : RolloutTrace
        ``n_frames`` recorded steps of ``A`` vehicles (vehicle 0 the ego).
    camera : Camera
        The scenario's camera (:func:`avrisk.assembly.parts.camera_from_spec`),
        on the CPU.

    Returns
    -------
    CameraFrames
        ``T = trace.n_frames`` images.
    """
    n = trace.n_frames

    def per_step(values: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(values[:n]), dtype=torch.float32)

    def per_vehicle(values: np.ndarray) -> torch.Tensor:
        return per_step(np.broadcast_to(values, (n, values.shape[-1])))

    state = VehicleState(
        x=per_step(trace.x),
        y=per_step(trace.y),
        heading=per_step(trace.heading),
        speed=per_step(trace.speed),
        length=per_vehicle(trace.length),
        width=per_vehicle(trace.width),
    )
    with torch.no_grad():
        frame = camera(state)
    return CameraFrames(
        rgb=frame.rgb.permute(0, 2, 3, 1).numpy(),
        depth=frame.depth.numpy(),
        segmentation=frame.segmentation.numpy(),
    )
