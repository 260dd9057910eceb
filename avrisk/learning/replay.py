"""Closed-loop replays of human car following, and their distances to the record.

A *window* is ``T`` steps of one NGSIM car-following episode. In a replay the
follower starts from its recorded state and is driven by a model in the
simulator while its leader replays the recorded speed profile (a classic
car-following validation; the follower's actions change its own future
states, so it is closed loop). Comparing the simulated follower with the
recorded one measures realism (:func:`replay_distances`);
:func:`avrisk.learning.training.sampling_noise.calibrate_noise` uses replays of
*training* windows to choose how much of the network's action noise to sample.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from scipy import stats
from torch import Tensor

from avrisk.learning.ngsim.lateral import LaneCentres, lateral_tracks
from avrisk.learning.ngsim.samples import (
    DEFAULT_WIDTH,
    I80_N_LANES,
    CarFollowingPairs,
    LateralPairs,
    episode_bounds,
)
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = [
    "BANDS",
    "CONGESTED_BELOW",
    "CarFollowingWindows",
    "ReplayLeader",
    "ReplayResult",
    "car_following_windows",
    "replay",
    "replay_distances",
    "replay_setup",
    "window_bands",
]

DT = 0.1  # [s] NGSIM sampling period and simulator step


@dataclass(frozen=True)
class CarFollowingWindows:
    """Recorded car-following windows: ``W`` windows of ``T`` steps.

    Attributes
    ----------
    v_f, v_l : ndarray of shape (W, T+1)
        Follower and leader speed [m/s].
    gap : ndarray of shape (W, T+1)
        Bumper-to-bumper gap [m].
    offset : ndarray of shape (W, T+1)
        Follower's lateral offset from its lane centre [m] (0 where the data
        have no lateral position).
    has_lateral : ndarray of bool, shape (W,)
        The window comes from the lateral file.
    len_f, len_l, width_f : ndarray of shape (W,)
        Follower length, leader length, follower width [m].
    lane : ndarray of int, shape (W,)
        avrisk lane index on the scenario road.
    heading : ndarray of shape (W,)
        Follower's initial heading offset [rad].
    """

    v_f: NDArray[np.float64]
    v_l: NDArray[np.float64]
    gap: NDArray[np.float64]
    offset: NDArray[np.float64]
    has_lateral: NDArray[np.bool_]
    len_f: NDArray[np.float64]
    len_l: NDArray[np.float64]
    width_f: NDArray[np.float64]
    lane: NDArray[np.int64]
    heading: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.len_f)

    @property
    def n_steps(self) -> int:
        """Steps ``T`` per window."""
        return self.v_f.shape[1] - 1

    def take(self, index: Any) -> CarFollowingWindows:
        """Windows ``index``."""
        return dataclasses.replace(
            self,
            **{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)},
        )

    def sample(self, n: int, seed: int) -> CarFollowingWindows:
        """``n`` windows drawn at random without replacement, in their order."""
        pick = np.random.default_rng(seed).permutation(len(self))
        return self.take(np.sort(pick[:n]))


#: A window whose recorded leader's mean speed is below this is congested [m/s].
CONGESTED_BELOW = 5.0
#: The speed bands, in the order of the tables.
BANDS = ("congested", "flowing")


def window_bands(windows: CarFollowingWindows) -> NDArray[np.str_]:
    """Each window's speed band, by its recorded leader's mean speed.

    The leader is replayed as recorded, so the band is the traffic the window
    imposes, the same for the humans and every model driving it.

    Returns
    -------
    ndarray of str, shape (W,)
        ``"congested"`` below :data:`CONGESTED_BELOW`, else ``"flowing"``.
    """
    slow = windows.v_l.mean(axis=1) < CONGESTED_BELOW
    return np.where(slow, BANDS[0], BANDS[1])


def _cut(
    starts: NDArray[Any], ends: NDArray[Any], n_steps: int, gap: NDArray[np.float64]
) -> Iterator[int]:
    """First rows of the episodes' non-overlapping windows whose gap stays > 0."""
    for s, e in zip(starts, ends, strict=True):
        for w in range(s, e - n_steps, n_steps):
            if gap[w : w + n_steps + 1].min() > 0.0:
                yield w


def car_following_windows(
    pairs: CarFollowingPairs,
    lateral: LateralPairs,
    centres: LaneCentres | None,
    n_steps: int,
    road: Road,
) -> CarFollowingWindows:
    """Non-overlapping windows of ``n_steps`` from both I-80 files.

    A window whose recorded gap is not positive at some step is left out:
    there the two vehicles overlap lengthwise, side by side (a lateral-file
    leader assigned while still in the next lane), which is no car
    following, and its replay would start or end in a collision that no
    follower can avoid and every model would be charged with.

    Parameters
    ----------
    pairs : CarFollowingPairs
        Already restricted to the wanted split.
    lateral : LateralPairs
        Already restricted to the wanted split.
    centres : LaneCentres or None
        Lane centre lines (fitted on the training split); None only without
        lateral pairs.
    n_steps : int
        ``T``.
    road : Road
        The scenario road (lanes mapped as in the demonstrations).

    Returns
    -------
    CarFollowingWindows
    """
    cols: dict[str, list[Any]] = {
        f: [] for f in CarFollowingWindows.__dataclass_fields__
    }
    median_len = float(np.median(pairs.leader_length)) if len(pairs) else 4.5
    s, e = episode_bounds(pairs.pair_id)
    for w in _cut(s, e, n_steps, pairs.gap):
        sl = slice(w, w + n_steps + 1)
        lane = int(pairs.lane[w])
        cols["v_f"].append(pairs.v_follower[sl])
        cols["v_l"].append(pairs.v_leader[sl])
        cols["gap"].append(pairs.gap[sl])
        cols["offset"].append(np.zeros(n_steps + 1))
        cols["has_lateral"].append(False)
        cols["len_f"].append(median_len)
        cols["len_l"].append(pairs.leader_length[w])
        cols["width_f"].append(DEFAULT_WIDTH)
        ok = 1 <= lane <= I80_N_LANES
        cols["lane"].append(min(I80_N_LANES - lane, road.n_lanes - 1) if ok else 2)
        cols["heading"].append(0.0)
    if len(lateral):
        if centres is None:
            raise ValueError("lateral pairs need lane centre lines")
        offset, heading, _ = lateral_tracks(lateral, centres)
        s, e = episode_bounds(lateral.pair_id)
        for w in _cut(s, e, n_steps, lateral.gap):
            sl = slice(w, w + n_steps + 1)
            cols["v_f"].append(lateral.speed[sl])
            cols["v_l"].append(lateral.leader_speed[sl])
            cols["gap"].append(lateral.gap[sl])
            cols["offset"].append(offset[sl])
            cols["has_lateral"].append(True)
            cols["len_f"].append(lateral.length[w])
            cols["len_l"].append(lateral.leader_length[w])
            cols["width_f"].append(lateral.width[w])
            cols["lane"].append(
                min(I80_N_LANES - int(lateral.lane[w]), road.n_lanes - 1)
            )
            cols["heading"].append(heading[w])
    shape = (0, n_steps + 1)
    arrays = {
        k: np.asarray(v)
        if v
        else np.zeros(shape if k in ("v_f", "v_l", "gap", "offset") else 0)
        for k, v in cols.items()
    }
    return CarFollowingWindows(**arrays)


class ReplayLeader:
    """Vehicle 1 replays an acceleration profile; vehicle 0 is driven by a model.

    Parameters
    ----------
    follower : Actor
        Acts for both vehicles (controls both); its vehicle-1 action is
        overridden.
    leader_accel : Tensor of shape (W, T)
        Leader acceleration per step [m/s^2] (steering 0: straight ahead).
    """

    def __init__(self, follower: Any, leader_accel: Tensor) -> None:
        self.follower = follower
        self.controlled = follower.controlled
        self.noise = follower.noise
        self.leader_accel = leader_accel

    def init(self, obs: Observation, params: Any) -> Any:
        """The follower model's initial state."""
        return self.follower.init(obs, params)

    def act(self, obs: Observation, state: Any, noise: Any) -> tuple[Action, Any]:
        """Follower's action in column 0, the replayed leader's in column 1."""
        action, state = self.follower.act(obs, state, noise)
        accel, steer = action.accel.clone(), action.steer.clone()
        accel[:, 1] = self.leader_accel[:, obs.step].to(accel)
        steer[:, 1] = 0.0
        return Action(accel=accel, steer=steer), state


@dataclass(frozen=True)
class ReplayResult:
    """The simulated follower in every window.

    Attributes
    ----------
    v, v_l, gap, offset : ndarray of shape (W, T+1)
        Follower speed, leader speed [m/s], gap [m], lateral offset from the
        initial lane centre [m].
    alive : ndarray of bool, shape (W, T+1)
        Frame simulated (false after a collision with the leader).
    crash, offroad : ndarray of bool, shape (W,)
    """

    v: NDArray[np.float64]
    v_l: NDArray[np.float64]
    gap: NDArray[np.float64]
    offset: NDArray[np.float64]
    alive: NDArray[np.bool_]
    crash: NDArray[np.bool_]
    offroad: NDArray[np.bool_]

    def take(self, index: Any) -> ReplayResult:
        """The replays ``index``."""
        return dataclasses.replace(
            self,
            **{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)},
        )


def replay_setup(
    windows: CarFollowingWindows, road: Road
) -> tuple[Simulator, VehicleState, Callable[[Any], ReplayLeader]]:
    """The simulator and initial state of a replay of ``windows``.

    Parameters
    ----------
    windows : CarFollowingWindows
        ``W`` windows of ``T`` steps.
    road : Road

    Returns
    -------
    sim : Simulator
        Horizon ``T`` steps of ``DT``; measure :class:`~avrisk.safety.MinTTC`.
    state : VehicleState
        Fields of shape (W, 2): the follower (vehicle 0) at its recorded
        state, the leader ahead at the recorded gap.
    replay_leader : callable
        ``replay_leader(follower_model)`` wraps a follower model (built for
        ``W`` rollouts of 2 vehicles, controlling both) into the actor whose
        leader replays its recorded speed profile.
    """
    n = len(windows)
    w = windows
    centre = road.lane_center_y(w.lane)
    x_l = 0.5 * w.len_f + w.gap[:, 0] + 0.5 * w.len_l
    zeros = np.zeros(n)
    follower = [
        zeros,
        centre + w.offset[:, 0],
        w.heading,
        w.v_f[:, 0],
        w.len_f,
        w.width_f,
    ]
    leader = [x_l, centre, zeros, w.v_l[:, 0], w.len_l, np.full(n, DEFAULT_WIDTH)]
    rows = np.stack([np.stack(follower, -1), np.stack(leader, -1)], axis=1)
    sim = Simulator(road, SimConfig(horizon=w.n_steps * DT), measure=MinTTC(n_rays=1))
    state = sim.prepare(VehicleState.from_rows(rows.tolist()))
    leader_accel = torch.as_tensor(np.diff(w.v_l, axis=1) / DT, dtype=torch.float32)
    return sim, state, lambda model: ReplayLeader(model, leader_accel)


def replay(
    windows: CarFollowingWindows, follower_model: Any, road: Road, *, seed: int = 0
) -> ReplayResult:
    """Simulate the follower of every window with a driver model.

    Parameters
    ----------
    windows : CarFollowingWindows
    follower_model : Actor
        Built for ``B = len(windows)`` rollouts of 2 vehicles, controlling both.
    road : Road
    seed : int, default=0
        Rollout ``w`` has seed ``seed * 1_000_003 + w``.

    Returns
    -------
    ReplayResult
    """
    w = windows
    sim, state, replay_leader = replay_setup(w, road)
    seeds = torch.as_tensor(seed * 1_000_003 + np.arange(len(w)), dtype=torch.int64)
    res = sim.run(state, [replay_leader(follower_model)], seeds, record_trace=True)
    tr = res.trace
    centre = road.lane_center_y(w.lane)
    gap = (tr.x[..., 1] - tr.x[..., 0]).double().numpy() - 0.5 * (w.len_f + w.len_l)[
        :, None
    ]
    return ReplayResult(
        v=tr.speed[..., 0].double().numpy(),
        v_l=tr.speed[..., 1].double().numpy(),
        gap=gap,
        offset=tr.y[..., 0].double().numpy() - centre[:, None],
        alive=tr.alive.numpy(),
        crash=res.crash.numpy(),
        offroad=res.offroad.numpy(),
    )


def _accel_jerk(
    v: NDArray[Any], alive: NDArray[Any]
) -> tuple[NDArray[Any], NDArray[Any]]:
    a = np.diff(v, axis=1) / DT
    ok_a = alive[:, 1:] & alive[:, :-1]
    j = np.diff(a, axis=1) / DT
    ok_j = ok_a[:, 1:] & ok_a[:, :-1]
    return a[ok_a], j[ok_j]


def replay_distances(
    windows: CarFollowingWindows, result: ReplayResult
) -> dict[str, float]:
    """Kolmogorov-Smirnov distances between simulated and recorded followers.

    Parameters
    ----------
    windows : CarFollowingWindows
    result : ReplayResult

    Returns
    -------
    dict of str to float
        ``"speed"``, ``"accel"``, ``"jerk"``, ``"gap"``, ``"offset"`` (lateral
        windows only) KS statistics, and ``"crash_rate"``: the fraction of
        windows that end in a collision with the leader.
    """
    human_alive = np.ones_like(windows.v_f, dtype=bool)
    ha, hj = _accel_jerk(windows.v_f, human_alive)
    sa, sj = _accel_jerk(result.v, result.alive)
    lat = windows.has_lateral
    out = {
        "speed": stats.ks_2samp(result.v[result.alive], windows.v_f.ravel()).statistic,
        "accel": stats.ks_2samp(sa, ha).statistic,
        "jerk": stats.ks_2samp(sj, hj).statistic,
        "gap": stats.ks_2samp(result.gap[result.alive], windows.gap.ravel()).statistic,
        "crash_rate": float(result.crash.mean()),
    }
    if lat.any():
        sim_off = result.offset[lat][result.alive[lat]]
        out["offset"] = stats.ks_2samp(sim_off, windows.offset[lat].ravel()).statistic
    return {k: float(v) for k, v in out.items()}
