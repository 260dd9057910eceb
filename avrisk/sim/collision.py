"""Crash, road-departure and reversing indicators of every vehicle.

Rules (decided here, used everywhere):

* **Crash**: the interiors of two rectangles intersect (exact separating-axis
  test, :func:`avrisk.sim.geometry.boxes_overlap`). Touching along an edge or at
  a corner is not a crash.
* **Road departure**: some corner of the rectangle lies strictly beyond a road
  edge (``y < 0`` or ``y > road.width``). Touching the edge line is on the road.
* **Reversing**: the vehicle moves against the road direction, i.e. its
  velocity along ``x``, ``speed * cos(heading)``, is negative (backing up, or
  driving forward after turning around).
"""

from __future__ import annotations

import torch
from torch import Tensor

from avrisk.sim.geometry import boxes_overlap
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

__all__ = ["offroad", "pairwise_overlap", "reversing"]


def pairwise_overlap(state: VehicleState, cos: Tensor, sin: Tensor) -> Tensor:
    """Which pairs of vehicles overlap (crash), per rollout.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A).
    cos, sin : Tensor of shape (..., A)
        Cosine and sine of ``state.heading``.

    Returns
    -------
    Tensor of bool, shape (..., A, A)
        Symmetric; the diagonal is false.
    """
    hl = 0.5 * state.length
    hw = 0.5 * state.width

    def a(t: Tensor) -> Tensor:
        return t.unsqueeze(-1)

    def b(t: Tensor) -> Tensor:
        return t.unsqueeze(-2)

    hit = boxes_overlap(
        a(state.x), a(state.y), a(cos), a(sin), a(hl), a(hw),
        b(state.x), b(state.y), b(cos), b(sin), b(hl), b(hw),
    )  # fmt: skip
    n = state.n_vehicles
    eye = torch.eye(n, dtype=torch.bool, device=hit.device)
    return hit & ~eye


def offroad(state: VehicleState, cos: Tensor, sin: Tensor, road: Road) -> Tensor:
    """Whether a corner of each vehicle lies beyond a road edge.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A).
    cos, sin : Tensor of shape (..., A)
        Cosine and sine of ``state.heading``.
    road : Road

    Returns
    -------
    Tensor of bool, shape (..., A)
    """
    # Lateral half-extent of the rotated rectangle.
    extent = 0.5 * state.length * torch.abs(sin) + 0.5 * state.width * torch.abs(cos)
    return (state.y - extent < 0.0) | (state.y + extent > road.width)


def reversing(state: VehicleState, cos: Tensor) -> Tensor:
    """Whether each vehicle moves against the road direction.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A).
    cos : Tensor of shape (..., A)
        Cosine of ``state.heading``.

    Returns
    -------
    Tensor of bool, shape (..., A)
    """
    return state.speed * cos < 0.0
