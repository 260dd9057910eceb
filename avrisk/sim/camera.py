"""The camera seam: what a camera gives an actor, and what the simulator asks of it.

The simulator owns this interface; :mod:`avrisk.render` implements it (a
batched ray caster). A camera is mounted on the ego (vehicle 0) and maps the
state of a batch to one frame per rollout::

    frame = camera(state)   # state (B, A) -> CameraFrame, fields (B, ...)

The simulator calls it only when some actor reads the image (class attribute
``reads_camera = True``, see :func:`reads_camera`); otherwise
``Observation.camera`` is None and nothing is rendered. A camera must keep the
simulator's contracts: a rollout's frame depends only on that rollout's rows
of the state (elementwise along the batch), and it runs under
``torch.compile(fullgraph=True)`` when the simulator compiles its step.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Protocol, runtime_checkable

from torch import Tensor

from avrisk.sim.state import VehicleState
from avrisk.tensors.tensors import TensorDataclass

__all__ = ["Camera", "CameraFrame", "SemanticClass", "reads_camera"]


class SemanticClass(IntEnum):
    """Semantic segmentation labels of a :class:`CameraFrame` (int8)."""

    #: Nothing hit: above the horizon.
    SKY = 0
    #: The road surface between the markings.
    ROAD = 1
    #: A (dashed) line between two lanes.
    LANE_MARKING = 2
    #: The solid line along either road edge.
    ROAD_EDGE = 3
    #: Any other vehicle's box.
    VEHICLE = 4
    #: The ground beyond the road edges.
    OFFROAD = 5


@dataclass(frozen=True)
class CameraFrame(TensorDataclass):
    """The ego camera's image of every rollout of a batch, ``H`` x ``W`` pixels.

    Row 0 is the top of the image, column 0 its left. The fields share the
    batch dimension ``B``; ``shape`` is (B, H, W).

    Attributes
    ----------
    depth : Tensor of shape (B, H, W)
        Distance along the camera's optical axis to what the pixel's centre
        ray hits [m] (the z-buffer convention); ``inf`` for sky.
    segmentation : Tensor of int8, shape (B, H, W)
        :class:`SemanticClass` of what the pixel's centre ray hits.
    rgb : Tensor of shape (B, 3, H, W)
        Colour in ``[0, 1]``, channels first (as convolutions take it).
    """

    depth: Tensor  # [B, H, W] m
    segmentation: Tensor  # [B, H, W] int8
    rgb: Tensor  # [B, 3, H, W] in [0, 1]

    @property
    def height(self) -> int:
        """Image height ``H`` [pixels]."""
        return self.depth.shape[-2]

    @property
    def width(self) -> int:
        """Image width ``W`` [pixels]."""
        return self.depth.shape[-1]


@runtime_checkable
class Camera(Protocol):
    """A camera on the ego: the state of a batch to one frame per rollout."""

    def __call__(self, state: VehicleState) -> CameraFrame:
        """The frames of a state with fields of shape (B, A); vehicle 0 is the ego."""
        ...


def reads_camera(actor: Any) -> bool:
    """Whether an actor reads ``obs.camera`` (its ``reads_camera``, default False).

    Examples
    --------
    >>> class Driver:
    ...     reads_camera = True
    >>> reads_camera(Driver()), reads_camera(object())
    (True, False)
    """
    return bool(getattr(actor, "reads_camera", False))
