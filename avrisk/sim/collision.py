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
* **Contact mechanism** of a crash, from the centre of the vehicle hit seen in
  the ego's frame (``ahead`` along the ego's heading, ``left`` across it): in
  the ego's lane-width band (``|left| <= lane_width / 2``) the ego rear-ends
  it (``ahead >= 0``) or is hit from behind (``ahead < 0``); outside the band
  it is a side contact (:class:`Contact`).
"""

from __future__ import annotations

from enum import IntEnum

import torch
from torch import Tensor

from avrisk.sim.geometry import boxes_overlap
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

__all__ = ["Contact", "contact", "offroad", "pairwise_overlap", "reversing"]


class Contact(IntEnum):
    """Contact mechanism of the ego's crash (``RolloutResult.contact``, int8)."""

    #: No crash.
    NONE = 0
    #: The ego runs into the vehicle ahead in its lane-width band.
    REAR_END = 1
    #: A vehicle behind in the ego's lane-width band runs into the ego.
    FROM_BEHIND = 2
    #: The vehicle hit is beside the ego, outside its lane-width band.
    SIDE = 3


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


def contact(
    state: VehicleState, cos: Tensor, sin: Tensor, other: Tensor, lane_width: float
) -> Tensor:
    """Contact mechanism if the ego (vehicle 0) crashed into vehicle ``other``.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (B, A).
    cos, sin : Tensor of shape (B, A)
        Cosine and sine of ``state.heading``.
    other : Tensor of int64, shape (B,)
        Index of the other vehicle, in ``1..A-1``.
    lane_width : float
        Width of the ego's band [m].

    Returns
    -------
    Tensor of int8, shape (B,)
        :class:`Contact` code (never ``NONE``; the caller masks rollouts
        without a crash).

    Examples
    --------
    >>> s = VehicleState.from_rows(
    ...     [[[0.0, 2.0, 0.0, 9.0, 4.0, 2.0], [4.5, 2.5, 0.0, 5.0, 4.0, 2.0]],
    ...      [[0.0, 2.0, 0.0, 9.0, 4.0, 2.0], [1.0, 4.1, 0.0, 5.0, 4.0, 2.0]]]
    ... )
    >>> c, s_ = s.cos_sin
    >>> contact(s, c, s_, torch.tensor([1, 1]), 3.7).tolist()
    [1, 3]
    """
    index = other.unsqueeze(-1)
    dx = state.x.gather(-1, index)[:, 0] - state.x[:, 0]
    dy = state.y.gather(-1, index)[:, 0] - state.y[:, 0]
    c, s = cos[:, 0], sin[:, 0]
    ahead = c * dx + s * dy
    left = c * dy - s * dx
    in_band = torch.abs(left) <= 0.5 * lane_width
    code = torch.where(
        in_band,
        torch.where(ahead >= 0.0, int(Contact.REAR_END), int(Contact.FROM_BEHIND)),
        int(Contact.SIDE),
    )
    return code.to(torch.int8)
