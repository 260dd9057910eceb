"""Part B: lane changes of the learned drivers against the held-out US-101 vehicles.

The learned drivers change lanes through the layer of
:mod:`avrisk.agents.drivers.lane_change`. Everything is measured with one
detector (:mod:`avrisk.learning.ngsim.lane_changes`) on the US-101 vehicles and on
the simulator's traces alike, in random six-lane traffic (:class:`Scenes`:
6 vehicles per scene, 60 s), every vehicle driven by the same model, the
learned network with ``xi ~ N(mu0, Sigma0)`` per scene. Compared
(:func:`evaluate`): the network with its lane-change layer (sampled and mean
actions), without it, and IDM+MOBIL on the same scenes; per model the lane
changes per vehicle-hour with their exact Poisson interval (target: within
+-30% of the held-out humans' rate), the duration and peak lateral speed of
the manoeuvres, and collisions between any two vehicles per vehicle-hour, all
of them and those of a lane change (:data:`AFTER_CHANGE`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.lane_change import LaneChangeParams, LaneChangingDriver
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.idm import IDMDriver
from avrisk.learning.imitation.simulated_demonstrations import random_highway_scenes
from avrisk.learning.ngsim.lane_changes import (
    LaneChanges,
    detect_lane_changes,
    exposure_seconds,
)
from avrisk.learning.ngsim.us101_lane_changes import (
    LaneChangeStatistics,
    lane_change_statistics,
)
from avrisk.realism.car_following import Progress
from avrisk.realism.metrics import DT, event_rate
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.collision import pairwise_overlap

__all__ = [
    "AFTER_CHANGE",
    "HORIZON",
    "N_VEHICLES",
    "RATE_TOLERANCE",
    "Scenes",
    "TrafficLaneChanges",
    "collision_onsets",
    "evaluate",
    "frame_states",
    "lane_changing_drivers",
    "measure",
    "summarise_lane_changes",
]

#: Vehicles per scene.
N_VEHICLES = 6
#: Length of a scene [s].
HORIZON = 60.0
#: A collision this soon after a change ends still counts as the change's [s].
AFTER_CHANGE = 1.0
#: The target: lane changes per vehicle-hour within this share of the humans'.
RATE_TOLERANCE = 0.30


class Scenes:
    """Random six-lane scenes, their ``xi`` draws and seeds (one per scene).

    Parameters
    ----------
    n : int
        Scenes ``B``.
    seed : int
        Seeds the scenes, then the ``xi`` draws; rollout ``b`` has noise seed
        ``b + 1_000_003 seed``.
    horizon : float
        [s].
    fam : FixedCovNormal
        ``xi ~ P0`` (:func:`avrisk.scenario.xi_base_family`).

    Attributes
    ----------
    road : Road
        The six-lane road.
    init : VehicleState
        Fields of shape (B, N_VEHICLES).
    idm : IDMParams
        Heterogeneous IDM+MOBIL drivers of the scenes, fields (B, N_VEHICLES).
    xi : Tensor of shape (B, 404)
    seeds : Tensor of int64, shape (B,)
    sim : Simulator
    """

    def __init__(self, n: int, seed: int, horizon: float, fam: Any) -> None:
        rng = np.random.default_rng(seed)
        self.road = Road()
        self.init, self.idm = random_highway_scenes(n, N_VEHICLES, self.road, rng)
        self.xi = torch.as_tensor(fam.sample(n, rng), dtype=torch.float32)
        self.seeds = torch.arange(n, dtype=torch.int64) + 1_000_003 * seed
        self.sim = Simulator(
            self.road, SimConfig(horizon=horizon), measure=MinTTC(n_rays=1)
        )

    def run(self, actor: Any, params: list) -> Any:
        """The trace of every scene driven by ``actor`` (all vehicles)."""
        res = self.sim.run(
            self.init, [actor], self.seeds, params=params, record_trace=True
        )
        return res.trace


def frame_states(trace: Any, init: VehicleState) -> Iterator[VehicleState]:
    """The vehicles of every frame of a trace, fields of shape (B, A)."""
    for k in range(trace.x.shape[1]):
        yield VehicleState(
            trace.x[:, k],
            trace.y[:, k],
            trace.heading[:, k],
            trace.speed[:, k],
            init.length,
            init.width,
        )


def collision_onsets(trace: Any, init: VehicleState) -> NDArray[np.int64]:
    """``(scene, i, j, frame)`` of every new overlap of vehicles ``i < j``, (K, 4)."""
    rows, prev = [], None
    for k, st in enumerate(frame_states(trace, init)):
        now = pairwise_overlap(st, *st.cos_sin) & trace.alive[:, k, None, None]
        if prev is not None:
            b, i, j = torch.nonzero(torch.triu(now & ~prev, diagonal=1), as_tuple=True)
            rows += [
                (int(bb), int(ii), int(jj), k)
                for bb, ii, jj in zip(b, i, j, strict=True)
            ]
        prev = now
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


@dataclass(frozen=True)
class TrafficLaneChanges:
    """Lane changes and collisions of every vehicle of a batch of scenes.

    Attributes
    ----------
    changes : LaneChanges
        Every change; ``track`` is ``scene * A + vehicle``.
    vehicles : int
        ``B A``.
    hours : float
        Exposure to a change: ``B A`` times a trace's duration less the
        detector's ``min_stay`` [vehicle-h].
    driven_hours : float
        ``B A`` times a trace's duration [vehicle-h].
    collisions : int
        Overlap onsets between any two vehicles.
    lc_collisions : int
        Those while one of the two changes lanes or within
        :data:`AFTER_CHANGE` after.
    """

    changes: LaneChanges
    vehicles: int
    hours: float
    driven_hours: float
    collisions: int
    lc_collisions: int

    def statistics(self) -> LaneChangeStatistics:
        """Rate with its interval, and the quantiles of the manoeuvres."""
        ch = self.changes
        return lane_change_statistics(
            self.vehicles,
            self.hours * 3600.0,
            ch.direction,
            ch.duration,
            ch.peak_lateral_speed,
        )


def measure(
    trace: Any, init: VehicleState, lane_width: float, noise: float
) -> TrafficLaneChanges:
    """Lane changes, exposure, collisions and lane-change collisions of a trace.

    Parameters
    ----------
    trace : Trace
        Of ``B`` scenes of ``A`` vehicles; ``trace.y`` of shape (B, T+1, A) [m].
    init : VehicleState
        The scenes' initial state (vehicle sizes).
    lane_width : float
        [m].
    noise : float
        Lateral speed of lane keeping of the detector [m/s].

    Returns
    -------
    TrafficLaneChanges
    """
    y = trace.y.numpy()  # (B, T+1, A)
    b, frames, a = y.shape
    changes = LaneChanges.concat(
        [
            detect_lane_changes(
                y[i, :, j],
                DT,
                lane_width=lane_width,
                noise_speed=noise,
                track=i * a + j,
            )
            for i in range(b)
            for j in range(a)
        ]
    )
    onsets = collision_onsets(trace, init)
    after = round(AFTER_CHANGE / DT)
    lc_hits = 0
    for scene, i, j, k in onsets:
        for v in (i, j):
            own = changes.track == scene * a + v
            if np.any((changes.start[own] <= k) & (k <= changes.end[own] + after)):
                lc_hits += 1
                break
    return TrafficLaneChanges(
        changes=changes,
        vehicles=b * a,
        hours=float(exposure_seconds(frames, DT)) * b * a / 3600.0,
        driven_hours=(frames - 1) * DT * b * a / 3600.0,
        collisions=len(onsets),
        lc_collisions=lc_hits,
    )


def lane_changing_drivers(
    net: DriverNet,
    road: Road,
    params: LaneChangeParams,
    stochastic: bool = True,
    guard: BrakeGuard | None = None,
) -> LaneChangingDriver:
    """The learned network with its lane-change layer, driving every vehicle."""
    every = torch.ones(N_VEHICLES, dtype=torch.bool)
    inner = LearnedDriver(net, controlled=every, stochastic=stochastic, guard=guard)
    return LaneChangingDriver(inner, road, params)


def evaluate(
    net: DriverNet,
    scenes: Scenes,
    params: LaneChangeParams,
    noise: float,
    progress: Progress | None = None,
    guard: BrakeGuard | None = None,
) -> dict[str, TrafficLaneChanges]:
    """Every compared model on ``scenes`` (see the module docstring).

    Parameters
    ----------
    net : DriverNet
    scenes : Scenes
    params : LaneChangeParams
        The lane-change layer's settings.
    noise : float
        The detector's lane-keeping speed [m/s] (the US-101 tables').
    progress : callable, optional
        ``progress(model, done, total)``.
    guard : BrakeGuard, optional
        The learned drivers' emergency brake (None: none).

    Returns
    -------
    dict of str to TrafficLaneChanges
    """
    every = torch.ones(N_VEHICLES, dtype=torch.bool)
    drivers = {
        "learned + lane changes (sampled actions)": (
            lane_changing_drivers(net, scenes.road, params, guard=guard),
            [scenes.xi],
        ),
        "learned + lane changes (mean actions)": (
            lane_changing_drivers(
                net, scenes.road, params, stochastic=False, guard=guard
            ),
            [scenes.xi],
        ),
        "learned, no lane changes (sampled actions)": (
            LearnedDriver(net, controlled=every, guard=guard),
            [scenes.xi],
        ),
        "IDM+MOBIL": (IDMDriver(scenes.idm, scenes.road), [None]),
    }
    out = {}
    for done, (name, (actor, actor_params)) in enumerate(drivers.items()):
        if progress is not None:
            progress(name, done, len(drivers))
        trace = scenes.run(actor, actor_params)
        out[name] = measure(trace, scenes.init, scenes.road.lane_width, noise)
    if progress is not None:
        progress("", len(drivers), len(drivers))
    return out


def _statistics(s: LaneChangeStatistics) -> dict[str, Any]:
    """JSON-ready statistics, None for NaN (no change to take quantiles of)."""
    return {k: None if v != v else v for k, v in s.to_dict().items()}


def summarise_lane_changes(
    results: dict[str, TrafficLaneChanges],
    held_out: LaneChangeStatistics,
    train: LaneChangeStatistics,
) -> dict[str, Any]:
    """Part B's figures, JSON-ready.

    Parameters
    ----------
    results : dict of str to TrafficLaneChanges
        :func:`evaluate`.
    held_out, train : LaneChangeStatistics
        The US-101 held-out and training vehicles'.

    Returns
    -------
    dict
        ``human_held_out``, ``human_train`` and per model ``models[name]``:
        the statistics (``rate``, ``rate_low``, ``rate_high`` [1/veh-h],
        ``duration_q10/50/90`` [s], ``peak_q10/50/90`` [m/s], None without
        changes, ...), ``vs_held_out`` (relative difference of the rate),
        ``target_met`` (within :data:`RATE_TOLERANCE`), ``collisions`` and
        ``lc_collisions`` as ``count``, ``per_hour`` of driving and ``ci95``,
        and ``driven_hours``.
    """
    models = {}
    for name, m in results.items():
        s = m.statistics()
        rel = s.rate / held_out.rate - 1
        models[name] = _statistics(s) | {
            "vs_held_out": rel,
            "target_met": bool(abs(rel) <= RATE_TOLERANCE),
            "collisions": event_rate(m.collisions, m.driven_hours),
            "lc_collisions": event_rate(m.lc_collisions, m.driven_hours),
            "driven_hours": m.driven_hours,
        }
    return {
        "human_held_out": _statistics(held_out),
        "human_train": _statistics(train),
        "models": models,
    }
