"""Who drives ahead of and behind each vehicle, in its lane and the lanes beside.

For every vehicle of every rollout at once, in four *queried* lanes (its own,
its target, the one to its left and the one to its right), the nearest vehicle
ahead (the leader) and behind (the follower) among those that occupy that lane
(drive in it, or are changing into it): what IDM and MOBIL
(:mod:`avrisk.agents.idm`) compare.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from avrisk.sim.geometry import min_argmin
from avrisk.sim.state import VehicleState

__all__ = ["Neighbours", "gather", "lane_neighbours", "own"]


def gather(t: Tensor, index: Tensor) -> Tensor:
    """``t[b, index[b, a, q]]`` for ``t`` (B, A) and ``index`` (B, A, Q)."""
    return t.gather(1, index.flatten(1)).view(index.shape)


def own(t: Tensor) -> Tensor:
    """A vehicle's own value, (B, A, 1), against its four queried lanes (B, A, 4)."""
    return t.unsqueeze(-1)


class Neighbours(NamedTuple):
    """The nearest vehicle ahead and behind in each queried lane, (B, A, 4).

    The queried lanes are a vehicle's own, its target, the one to its left
    and the one to its right.
    """

    lead_dx: Tensor  # how far the leader is ahead [m]; inf: none
    lead: Tensor  # the leader's index (int64)
    fol_dx: Tensor  # how far the follower is ahead (negative) [m]; -inf: none
    fol: Tensor  # the follower's index (int64)
    has_lead: Tensor  # bool
    has_fol: Tensor  # bool


def lane_neighbours(s: VehicleState, lane: Tensor, target: Tensor) -> Neighbours:
    """Leaders and followers of every vehicle in its four queried lanes.

    ``lane`` and ``target`` are each vehicle's lane and target lane, (B, A); a
    vehicle occupies both of its own.
    """
    n = s.n_vehicles
    # Queries per vehicle: own lane, target lane, left lane, right lane.
    query = torch.stack([lane, target, lane + 1, lane - 1], dim=-1)  # (B, A, 4)

    # Pairwise, (B, A, 1, A): how far vehicle j is ahead of vehicle a.
    dx = (s.x.unsqueeze(-2) - s.x.unsqueeze(-1)).unsqueeze(-2)
    # (B, A, 4, A): j occupies (drives in, or changes into) a's query lane.
    occupied = (lane[:, None, None, :] == query.unsqueeze(-1)) | (
        target[:, None, None, :] == query.unsqueeze(-1)
    )
    other = ~torch.eye(n, dtype=torch.bool, device=s.x.device).unsqueeze(-2)
    candidates = occupied & other
    # Nearest vehicle ahead and behind in each queried lane (lowest index on
    # a tie); min_argmin avoids the slow CPU path of Tensor.min(dim).
    lead_dx, lead = min_argmin(torch.where(candidates & (dx >= 0), dx, math.inf), -1)
    fol_gap, fol = min_argmin(torch.where(candidates & (dx < 0), -dx, math.inf), -1)
    fol_dx = -fol_gap
    has_lead = lead_dx < math.inf
    has_fol = fol_dx > -math.inf
    return Neighbours(lead_dx, lead, fol_dx, fol, has_lead, has_fol)
