"""What an actor sees at one step: privileged state, lidar, camera, lanes, flags."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from avrisk.sim.camera import CameraFrame
from avrisk.sim.lidar import LidarScan
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.mathops import wrap_angle
from avrisk.tensors.tensors import TensorDataclass

__all__ = ["LaneFeatures", "Observation", "lane_features"]


@dataclass(frozen=True)
class LaneFeatures(TensorDataclass):
    """Each vehicle's position relative to its lane and the road.

    The lane is the one containing the vehicle centre (clamped to the road).

    Attributes
    ----------
    lane : Tensor of int64, shape (B, A)
        Lane index, 0 = rightmost.
    lateral_offset : Tensor of shape (B, A)
        Centre minus lane centre line [m], positive to the left.
    heading_offset : Tensor of shape (B, A)
        Heading minus lane heading, wrapped to ``[-pi, pi]`` [rad].
    left_marking : Tensor of shape (B, A)
        Distance from the centre to the lane's left boundary [m].
    right_marking : Tensor of shape (B, A)
        Distance from the centre to the lane's right boundary [m].
    left_edge : Tensor of shape (B, A)
        Distance from the centre to the left road edge [m] (negative beyond it).
    right_edge : Tensor of shape (B, A)
        Distance from the centre to the right road edge [m] (negative beyond it).
    curvature : Tensor of shape (B, A)
        Lane curvature at the vehicle [1/m].
    """

    lane: Tensor  # [B, A] int64
    lateral_offset: Tensor  # [B, A] m
    heading_offset: Tensor  # [B, A] rad
    left_marking: Tensor  # [B, A] m
    right_marking: Tensor  # [B, A] m
    left_edge: Tensor  # [B, A] m
    right_edge: Tensor  # [B, A] m
    curvature: Tensor  # [B, A] 1/m


def lane_features(state: VehicleState, road: Road) -> LaneFeatures:
    """Lane-relative features of every vehicle on a straight road.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A).
    road : Road

    Returns
    -------
    LaneFeatures
        Fields of shape (..., A).
    """
    lane = road.lane_index(state.y)
    right = lane.to(state.y.dtype) * road.lane_width
    return LaneFeatures(
        lane=lane,
        lateral_offset=state.y - (right + 0.5 * road.lane_width),
        heading_offset=wrap_angle(state.heading),
        left_marking=(right + road.lane_width) - state.y,
        right_marking=state.y - right,
        left_edge=road.width - state.y,
        right_edge=state.y,
        curvature=torch.full_like(state.y, road.curvature),
    )


@dataclass(frozen=True)
class Observation:
    """Everything an actor may use at one step, for every vehicle.

    An ego policy reads vehicle 0's rows (``lidar.range[:, 0]``, ...) and may
    use the rest as privileged information; a driver reads the rows of the
    vehicles it controls.

    Attributes
    ----------
    state : VehicleState
        Privileged ground truth, fields of shape (B, A).
    lidar : LidarScan or None
        Each vehicle's lidar, fields of shape (B, A, R); None when the
        simulator runs without lidar (``n_lidar_beams = 0``) or when no actor
        reads it (``reads_lidar = False``, see :mod:`avrisk.sim.interfaces`).
    lane : LaneFeatures
        Fields of shape (B, A).
    collided : Tensor of bool, shape (B, A)
        The vehicle overlaps another one now.
    offroad : Tensor of bool, shape (B, A)
        A corner of the vehicle is beyond a road edge now.
    reversing : Tensor of bool, shape (B, A)
        The vehicle moves against the road direction now.
    seeds : Tensor of int64, shape (B,)
        Per-rollout seeds, for counter-based noise (:mod:`avrisk.tensors.noise`).
    step : int or Tensor of int64, shape () or (B,)
        Index ``t`` of this step; the action applies from ``t`` to ``t + 1``.
        A Python int in eager mode; a 0-d tensor under ``torch.compile`` (one
        graph for every step); one per rollout, shape (B,), when the rollouts
        of a batch are at different steps (some were restarted: the Gymnasium
        vector environment).
    dt : float
        Time step [s].
    camera : CameraFrame or None, default=None
        The ego camera's image, fields of shape (B, ...); None unless some
        actor reads it (``reads_camera = True``, see :mod:`avrisk.sim.camera`).
    """

    state: VehicleState
    lidar: LidarScan | None
    lane: LaneFeatures
    collided: Tensor  # [B, A] bool
    offroad: Tensor  # [B, A] bool
    reversing: Tensor  # [B, A] bool
    seeds: Tensor  # [B] int64
    step: int | Tensor
    dt: float
    camera: CameraFrame | None = None

    @property
    def time(self) -> float | Tensor:
        """Simulated time of this step [s]."""
        return self.step * self.dt
