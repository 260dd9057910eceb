"""Lane changes for the learned drivers: a discrete intention on top of the network.

The driver network (:class:`~avrisk.agents.drivers.LearnedDriver`) keeps its
lane: its lateral head steers the lateral offset from the lane centre to zero.
:class:`LaneChangingDriver` wraps it and gives every vehicle it controls an
intention -- keep, left or right -- and, once a change is under way, feeds the
network its offset from the *target* lane's centre instead, so that the
trained lateral head itself steers the vehicle over. Per vehicle and step:

1. **desire** (a hazard): a vehicle that keeps its lane and has no pending
   desire wants to change with probability ``1 - exp(-rate dt)`` per step
   (``rate`` [1/s] constant; its default is fitted to the US-101 training
   vehicles, which come without their neighbours, so it cannot depend on
   them). The
   side is the one whose lane offers more room ahead than the own lane
   (MOBIL's incentive in gap terms: ``min(gap, gap_cap)`` in the side lane
   minus that in the own lane), a fair coin between equal sides; a side
   without a lane is never chosen;
2. **gap acceptance**: a pending desire is carried out at the first step at
   which the target lane's nearest vehicles ahead and behind (any vehicle
   whose centre lies within ``OCCUPY_BAND`` lane widths of the target lane's
   centre line: in it, or on its way in or out) leave a bumper gap of at
   least ``min_gap`` and a time-to-collision (gap over closing speed, when
   closing) of at least ``min_ttc``; a desire not carried out within
   ``patience`` lapses. These two thresholds cannot be read off the data
   (the US-101 vehicles come without their neighbours): they are chosen in
   closed loop, in the simulator (``benchmarks/lane_change_realism.py``);
3. **manoeuvre**: the target lane switches to the side lane. Until the
   vehicle is within ``settle`` of the target centre, the network sees its
   lateral offset from the target centre clipped to ``+-offset_clip`` (and
   lane markings that fit it); the clip sets the pace (the network's lateral
   speed grows with the offset it sees: unclipped, a 3.7 m offset makes it
   cross at 3-6 m/s, humans at about 0.8), the trained head the profile.

A vehicle that keeps its lane gets exactly the network's inputs, so with no
desire a rollout is bit-identical to one of the bare network.

Randomness: two independent standard normals per vehicle and step give the
clock ``E = (z1^2 + z2^2) / 2 ~ Exp(1)`` (a desire arrives when
``E < rate dt``: probability ``1 - exp(-rate dt)``, with IEEE ``+ *`` only),
and a third gives the coin. They are the simulator's declared noise
(:class:`~avrisk.sim.interfaces.NoiseRequest`), regenerated from the rollout's
seed: when the wrapped driver samples its actions, the request extends its
stream by a leading axis, ``(3, A, 2)`` instead of ``(A, 2)``, of which slice
0 is bit for bit the noise the driver would get alone
(:func:`~avrisk.tensors.noise.normal` numbers elements in order); otherwise
it is a stream of its own, :data:`LANE_CHANGE_NOISE_STREAM`. So a rollout
depends only on its ``X`` and seed, alone or in any batch.

Examples
--------
>>> import torch
>>> from avrisk.agents.drivers.network import DriverNet
>>> from avrisk.safety import MinTTC
>>> from avrisk.sim import Road, SimConfig, Simulator, VehicleState
>>> road = Road(n_lanes=3)
>>> sim = Simulator(road, SimConfig(horizon=0.5), measure=MinTTC())
>>> state = VehicleState.from_rows([[0.0, 5.55, 0.0, 20.0, 4.8, 1.9]])
>>> inner = LearnedDriver(DriverNet(), controlled=torch.tensor([True]))
>>> driver = LaneChangingDriver(inner, road)
>>> sim.run(state, [driver], torch.tensor([0])).steps.tolist()
[5]
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
from torch import Tensor

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.sim.geometry import min_argmin
from avrisk.sim.interfaces import Action, NoiseRequest
from avrisk.sim.observation import Observation
from avrisk.sim.road import Road

__all__ = [
    "LANE_CHANGE_NOISE_STREAM",
    "OCCUPY_BAND",
    "LaneChangeParams",
    "LaneChangeState",
    "LaneChangingDriver",
    "target_lane_gaps",
]

#: Noise stream of the lane-change layer when the wrapped driver draws none.
LANE_CHANGE_NOISE_STREAM = 0x4C43  # "LC"
#: A vehicle occupies a lane when its centre is closer than this many lane
#: widths to the lane's centre line [-].
OCCUPY_BAND = 0.75
#: Normals per vehicle and step the layer uses (clock: 2, coin: 1; padded to
#: the wrapped driver's (A, 2) blocks: 2 blocks).
_BLOCKS = 2


@dataclass(frozen=True)
class LaneChangeParams:
    """Settings of :class:`LaneChangingDriver`.

    Parameters
    ----------
    rate : float, default=69.6 / 3600
        Hazard of a lane-change desire [1/s] (a vehicle keeping its lane).
        Default: fitted in closed loop to the US-101 training vehicles
        (:mod:`avrisk.learning.ngsim.us101_lane_changes`: 58.9 per vehicle-hour);
        desires that wait for a gap, and none arriving during a manoeuvre,
        make the simulated rate fall short of the hazard, so the hazard is
        58.90 x 58.90 / 49.87 (rounded), 49.87 being the simulated rate at a
        hazard of 58.90 (``benchmarks/lane_change_realism.py --calibrate``;
        BENCHMARKS.md).
    min_gap : float, default=8.0
        Least bumper gap to the target lane's vehicles ahead and behind [m].
        Default (with ``min_ttc``): the setting of a grid with the fewest
        lane-change collisions in closed loop among those that keep the rate
        within 5% of the grid's highest (same benchmark).
    min_ttc : float, default=6.0
        Least time-to-collision with them, when closing [s].
    patience : float, default=10.0
        A desire not carried out within this long lapses [s].
    offset_clip : float, default=0.5
        Largest lateral offset from the target centre the network sees while
        changing [m]. Default: of 0.4-0.7, the one whose median duration and
        peak lateral speed are closest to the US-101 training vehicles' (same
        benchmark).
    settle : float, default=0.3
        A change ends when the vehicle is this close to the target centre [m].
    gap_cap : float, default=50.0
        Room ahead beyond this counts as this when choosing a side [m].
    """

    rate: float = 69.6 / 3600.0  # [1/s]
    min_gap: float = 8.0  # [m]
    min_ttc: float = 6.0  # [s]
    patience: float = 10.0  # [s]
    offset_clip: float = 0.5  # [m]
    settle: float = 0.3  # [m]
    gap_cap: float = 50.0  # [m]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate) and self.rate >= 0):
            raise ValueError(f"rate must be finite and >= 0 [1/s]; got {self.rate}")
        for name in ("min_gap", "min_ttc", "patience"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)}")
        for name in ("offset_clip", "settle", "gap_cap"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0; got {getattr(self, name)}")


class LaneChangeState(NamedTuple):
    """Memory of :class:`LaneChangingDriver` (fields (B, A) but ``inner``).

    Attributes
    ----------
    inner : Any
        The wrapped driver's state.
    target : Tensor of int64
        Lane the vehicle keeps or changes to.
    changing : Tensor of bool
        A change is under way (not yet within ``settle`` of the target).
    pending : Tensor of int64
        Desired side waiting for a gap: ``+1`` left, ``-1`` right, 0 none.
    waited : Tensor of int64
        Steps the pending desire has waited.
    """

    inner: Any
    target: Tensor  # [B, A] int64
    changing: Tensor  # [B, A] bool
    pending: Tensor  # [B, A] int64
    waited: Tensor  # [B, A] int64


def target_lane_gaps(
    obs: Observation, lane: Tensor, lane_width: float
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Bumper gaps and closing speeds to the nearest vehicles of a lane.

    Parameters
    ----------
    obs : Observation
        Fields of shape (B, A).
    lane : Tensor of int64, shape (B, A, Q)
        ``Q`` lanes queried per vehicle.
    lane_width : float
        [m].

    Returns
    -------
    lead_gap, lead_closing, follow_gap, follow_closing : Tensor of shape (B, A, Q)
        Gap [m] to the nearest vehicle ahead occupying the lane (centre within
        :data:`OCCUPY_BAND` lane widths of its centre line; ``inf`` if none)
        and how fast the vehicle closes on it [m/s]; the same for the nearest
        vehicle behind (its closing speed on the vehicle).
    """
    s = obs.state
    n = s.n_vehicles
    centre = (lane.to(s.y.dtype) + 0.5) * lane_width  # (B, A, Q)
    # (B, A, Q, A): vehicle j occupies vehicle a's query lane q.
    occupied = (s.y[:, None, None, :] - centre.unsqueeze(-1)).abs() < (
        OCCUPY_BAND * lane_width
    )
    other = ~torch.eye(n, dtype=torch.bool, device=s.x.device)[None, :, None, :]
    dx = (s.x.unsqueeze(-2) - s.x.unsqueeze(-1)).unsqueeze(-2)  # (B, A, 1, A)
    half = 0.5 * (s.length.unsqueeze(-2) + s.length.unsqueeze(-1)).unsqueeze(-2)
    ahead = occupied & other & (dx >= 0)
    behind = occupied & other & (dx < 0)
    lead_dx, lead = min_argmin(torch.where(ahead, dx, math.inf), -1)
    back_dx, back = min_argmin(torch.where(behind, -dx, math.inf), -1)
    half_lead = half.expand_as(occupied).gather(-1, lead.unsqueeze(-1)).squeeze(-1)
    half_back = half.expand_as(occupied).gather(-1, back.unsqueeze(-1)).squeeze(-1)
    v = s.speed.unsqueeze(-1)  # (B, A, 1)

    def speed_of(index: Tensor) -> Tensor:
        return s.speed.gather(1, index.flatten(1)).view(index.shape)

    return (
        lead_dx - half_lead,
        v - speed_of(lead),
        back_dx - half_back,
        speed_of(back) - v,
    )


def _acceptable(gap: Tensor, closing: Tensor, p: LaneChangeParams) -> Tensor:
    """Gap at least ``min_gap`` and, when closing, TTC at least ``min_ttc``."""
    return (gap >= p.min_gap) & ((closing <= 0) | (gap >= p.min_ttc * closing))


class LaneChangingDriver:
    """A learned driver that changes lanes (see the module docstring); an actor.

    Parameters
    ----------
    inner : LearnedDriver
        Drives the vehicles; its ``controlled`` are the ones that change lanes.
    road : Road
    params : LaneChangeParams, default=LaneChangeParams()
    """

    def __init__(
        self, inner: LearnedDriver, road: Road, params: LaneChangeParams | None = None
    ) -> None:
        self.inner = inner
        self.road = road
        self.params = LaneChangeParams() if params is None else params
        self.controlled = inner.controlled
        self.reads_lidar = inner.reads_lidar
        n = int(inner.controlled.shape[0])
        own = inner.noise
        if own is None:
            self.noise = NoiseRequest(
                LANE_CHANGE_NOISE_STREAM,
                (_BLOCKS, n, 2),
                dtype=inner.net.input_mean.dtype,
            )
        elif own.shape == (n, 2):
            self.noise = NoiseRequest(own.stream, (1 + _BLOCKS, n, 2), own.dtype)
        else:
            raise ValueError(
                f"LaneChangingDriver wraps a driver drawing noise of shape ({n}, 2); "
                f"got {own.shape}"
            )

    def init(self, obs: Observation, params: Tensor | None) -> LaneChangeState:
        """Every vehicle keeps the lane it starts in; ``params`` go to ``inner``."""
        lane = obs.lane.lane
        return LaneChangeState(
            inner=self.inner.init(obs, params),
            target=lane,
            changing=torch.zeros_like(lane, dtype=torch.bool),
            pending=torch.zeros_like(lane),
            waited=torch.zeros_like(lane),
        )

    def _split_noise(self, noise: Tensor) -> tuple[Tensor | None, Tensor]:
        """(the inner driver's noise or None, the layer's (B, _BLOCKS, A, 2))."""
        if self.inner.noise is None:
            return None, noise
        return noise[:, 0], noise[:, 1:]

    def act(
        self, obs: Observation, state: LaneChangeState, noise: Tensor | None
    ) -> tuple[Action, LaneChangeState]:
        """Decide, steer the network towards the target lane, act; fields (B, A)."""
        assert noise is not None  # always requested
        inner_noise, z = self._split_noise(noise)
        p, road, s = self.params, self.road, obs.state
        lane = obs.lane.lane
        target, changing = state.target, state.changing
        dtype = s.y.dtype
        # A change ends close to the target centre.
        from_target = s.y - (target.to(dtype) + 0.5) * road.lane_width
        changing = changing & (from_target.abs() >= p.settle)
        keeping = ~changing
        target = torch.where(keeping, lane, target)

        # Room ahead and behind in the own lane and the lanes to each side.
        query = torch.stack([lane, lane + 1, lane - 1], dim=-1)  # (B, A, 3)
        lead_gap, lead_close, back_gap, back_close = target_lane_gaps(
            obs, query, road.lane_width
        )
        exists = torch.stack([lane >= 0, lane + 1 < road.n_lanes, lane >= 1], dim=-1)

        # 1. Desire: clock E ~ Exp(1) against rate dt; side by room ahead.
        clock = 0.5 * (z[:, 0, :, 0] * z[:, 0, :, 0] + z[:, 0, :, 1] * z[:, 0, :, 1])
        arrives = keeping & (state.pending == 0) & (clock < p.rate * obs.dt)
        room = torch.clamp_max(lead_gap, p.gap_cap)
        gain = torch.where(exists[..., 1:], room[..., 1:] - room[..., :1], -math.inf)
        coin_left = z[:, 1, :, 0] > 0
        left = (gain[..., 0] > gain[..., 1]) | (
            (gain[..., 0] == gain[..., 1]) & coin_left
        )
        side = torch.where(left, 1, -1)
        side = torch.where(exists[..., 1:].any(-1), side, 0)
        pending = torch.where(arrives, side, state.pending)
        waited = torch.where(arrives, 0, state.waited + 1)

        # 2. Gap acceptance in the pending side's lane.
        pick = torch.where(pending > 0, 1, 2).unsqueeze(-1)  # index into query

        def at(t: Tensor) -> Tensor:
            return t.gather(-1, pick).squeeze(-1)

        safe = _acceptable(at(lead_gap), at(lead_close), p) & _acceptable(
            at(back_gap), at(back_close), p
        )
        go = keeping & (pending != 0) & safe & at(exists)
        target = torch.where(go, lane + pending, target)
        changing = changing | go
        lapsed = waited.to(dtype) * obs.dt > p.patience
        pending = torch.where(go | lapsed, 0, pending)
        waited = torch.where(pending == 0, 0, waited)

        # 3. The network's lane inputs: the target lane's while changing.
        half = 0.5 * road.lane_width
        offset = torch.clamp(
            s.y - (target.to(dtype) + 0.5) * road.lane_width,
            -p.offset_clip,
            p.offset_clip,
        )
        lf = obs.lane
        shifted = dataclasses.replace(
            lf,
            lateral_offset=torch.where(changing, offset, lf.lateral_offset),
            left_marking=torch.where(changing, half - offset, lf.left_marking),
            right_marking=torch.where(changing, half + offset, lf.right_marking),
        )
        action, inner_state = self.inner.act(
            dataclasses.replace(obs, lane=shifted), state.inner, inner_noise
        )
        return action, LaneChangeState(inner_state, target, changing, pending, waited)
