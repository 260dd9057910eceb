"""Part A: car following on held-out NGSIM I-80 windows, in closed loop.

Every held-out window (:mod:`avrisk.realism.held_out`) is replayed
(:func:`avrisk.learning.replay.replay`): the simulated follower starts from the
recorded state, the leader replays its recorded speed profile, and the
follower is driven by a model -- the learned network at ``mu0``, with a fresh
``xi ~ N(mu0, Sigma0)`` per replay (sampled actions), the same draws on their
mean actions, and IDM (the bundled scenario's ``normal`` driver, lane changes
off: MOBIL would overtake the replayed leader). Each window is driven
``replicates`` times (its own noise seed and ``xi`` each time), so that rates
as low as the targets' (0.5 collisions per vehicle-hour) are resolved; the
humans drove it once.

:func:`run_part_a` gives, per model and for the humans, the distributions
(speed, acceleration, jerk, gap, TTC, lateral offset) and event counts
(:class:`Followers`); :func:`summarise_part_a` turns them into the report's
figures (percentiles, KS and W1 to the humans, rates per vehicle-hour with
exact Poisson intervals -- for collisions also with the windows as clusters,
since a window's replays share its leader -- and where the collisions
happened).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.idm import IDMDriver, IDMParams
from avrisk.learning.replay import CarFollowingWindows, ReplayResult, replay
from avrisk.realism.metrics import (
    DT,
    clustered_event_rate,
    event_rate,
    hard_brake_events,
    kinematics,
    ks_w1,
    lane_index_changes,
    percentiles,
    road_departures,
    stopped_fraction,
    ttc_samples,
)
from avrisk.sim import Road

__all__ = [
    "IDM_NORMAL",
    "IMPACT_COLUMNS",
    "QUANTITIES",
    "Followers",
    "PartA",
    "Progress",
    "followers",
    "learned_drivers",
    "recorded",
    "run_part_a",
    "summarise_part_a",
]

#: The bundled scenario's ``normal`` IDM+MOBIL driver.
IDM_NORMAL = {
    "desired_speed": 25.0,
    "time_headway": 1.5,
    "min_gap": 2.0,
    "max_accel": 1.5,
    "comfort_decel": 2.0,
    "politeness": 0.3,
    "lane_change_threshold": 0.2,
}

#: The distributions compared, with their units.
QUANTITIES = {
    "speed": "m/s",
    "accel": "m/s^2",
    "jerk": "m/s^3",
    "gap": "m",
    "ttc": "s",
    "offset": "m",
}

#: Columns of :attr:`Followers.impacts`.
IMPACT_COLUMNS = (
    "window",
    "step",
    "speed",
    "leader_speed",
    "hardest_decel",
    "human_hardest_decel",
    "leader_near_stop",
)

#: ``progress(what, done, total)``: called before the first model and after each.
Progress = Callable[[str, int, int], None]


def learned_drivers(
    net: DriverNet,
    fam: Any,
    n: int,
    rng: np.random.Generator,
    n_vehicles: int,
    guard: BrakeGuard | None = None,
) -> dict[str, LearnedDriver]:
    """The learned drivers compared: at ``mu0``, and with ``xi ~ P0`` per rollout.

    Each drives all ``n_vehicles``. The last one acts on its mean actions, as in
    the bundled default scenario (``learned_drivers: {actions: mean}``); the
    others sample, as in the paper.

    Parameters
    ----------
    net : DriverNet
    fam : FixedCovNormal
        ``xi ~ N(mu0, Sigma0)`` (:func:`avrisk.scenario.xi_base_family`).
    n : int
        Rollouts ``B``: ``n`` draws of ``xi``, shape (B, 404).
    rng : numpy.random.Generator
    n_vehicles : int
        ``A``.
    guard : BrakeGuard, optional
        Their emergency brake (None: none).

    Returns
    -------
    dict of str to LearnedDriver
    """
    every = torch.ones(n_vehicles, dtype=torch.bool)
    xi_draw = torch.as_tensor(fam.sample(n, rng), dtype=torch.float32)
    mu0 = torch.as_tensor(fam.mean, dtype=torch.float32)
    return {
        "learned mu0": LearnedDriver(net, mu0, controlled=every, guard=guard),
        "learned xi~P0": LearnedDriver(net, xi_draw, controlled=every, guard=guard),
        "learned xi~P0, mean actions": LearnedDriver(
            net, xi_draw, controlled=every, stochastic=False, guard=guard
        ),
    }


@dataclass(frozen=True)
class Followers:
    """What the followers of ``W`` windows did: one model's replays, or the humans.

    Attributes
    ----------
    samples : dict of str to ndarray
        Per :data:`QUANTITIES` key, the samples of all windows (alive frames;
        TTC closing only; lateral offset of the lateral-file windows only).
    hours : float
        Vehicle-hours driven, ``W T DT / 3600`` [h].
    hard_brakes, lane_changes, road_departures : int
        Event counts (windows in which the follower crosses a road edge,
        :func:`~avrisk.realism.metrics.road_departures`).
    gap_rmse : float
        Root mean square of the gap's difference to the record after ``T``
        steps [m].
    collisions_by_window : ndarray of int64, shape (W,)
        Collisions with the leader per window, summed over its replays
        (windows in the order of their first replay); :attr:`collisions` is
        their total.
    impacts : ndarray of shape (K, 7)
        One row per collision, columns :data:`IMPACT_COLUMNS`: held-out window,
        impact step, follower and leader speed then [m/s], the hardest
        simulated and recorded deceleration in the window [m/s^2], and
        whether the leader came to a near stop (< 0.5 m/s) [0 or 1].
    """

    samples: dict[str, NDArray[np.float64]]
    hours: float
    hard_brakes: int
    lane_changes: int
    road_departures: int
    gap_rmse: float
    collisions_by_window: NDArray[np.int64]
    impacts: NDArray[np.float64]

    @property
    def collisions(self) -> int:
        """Collisions with the leader, all windows together."""
        return int(self.collisions_by_window.sum())


def recorded(windows: CarFollowingWindows) -> ReplayResult:
    """The human followers of ``windows`` as a replay (every frame alive)."""
    none = np.zeros(len(windows), bool)
    return ReplayResult(
        v=windows.v_f,
        v_l=windows.v_l,
        gap=windows.gap,
        offset=windows.offset,
        alive=np.ones_like(windows.v_f, bool),
        crash=none,
        offroad=none,
    )


def followers(
    windows: CarFollowingWindows,
    result: ReplayResult,
    road: Road,
    labels: NDArray[np.int64],
) -> Followers:
    """Samples and events of ``result``, the replays of ``windows`` (or the record).

    Parameters
    ----------
    windows : CarFollowingWindows
        ``W`` windows of ``T`` steps.
    result : ReplayResult
        Their replays (or :func:`recorded`).
    road : Road
        The road they were replayed on.
    labels : ndarray of int64, shape (W,)
        Held-out window index of each (for :attr:`Followers.impacts`).

    Returns
    -------
    Followers
    """
    r = result
    kin = kinematics(r.v, r.alive)
    lat = windows.has_lateral
    y = r.offset + road.lane_center_y(windows.lane)[:, None]  # [m]
    return Followers(
        samples={
            "speed": kin.speed,
            "accel": kin.accel,
            "jerk": kin.jerk,
            "gap": r.gap[r.alive],
            "ttc": ttc_samples(r.gap, r.v, r.v_l, r.alive),
            "offset": r.offset[lat][r.alive[lat]],
        },
        hours=len(windows) * windows.n_steps * DT / 3600,
        hard_brakes=hard_brake_events(kin.accel_all, kin.accel_ok),
        lane_changes=lane_index_changes(y / road.lane_width, r.alive),
        road_departures=road_departures(y, 0.5 * windows.width_f, road.width, r.alive),
        gap_rmse=float(np.sqrt(np.mean((r.gap[:, -1] - windows.gap[:, -1]) ** 2))),
        collisions_by_window=_by_window(r.crash, labels),
        impacts=_impacts(windows, r, labels),
    )


def _by_window(events: NDArray[Any], labels: NDArray[np.int64]) -> NDArray[np.int64]:
    """Per-replay event counts summed per window (``labels``: window of each)."""
    _, first, which = np.unique(labels, return_index=True, return_inverse=True)
    counts = np.bincount(which, weights=events, minlength=len(first))
    return counts[np.argsort(first)].astype(np.int64)


def _impacts(
    windows: CarFollowingWindows, r: ReplayResult, labels: NDArray[np.int64]
) -> NDArray[np.float64]:
    rows = []
    for k in np.flatnonzero(r.crash):
        t = int(r.alive[k].sum()) - 1
        a = np.diff(r.v[k, : t + 1]) / DT
        rows.append(
            (
                labels[k],
                t,
                r.v[k, t],
                r.v_l[k, t],
                a.min() if a.size else 0.0,
                (np.diff(windows.v_f[k]) / DT).min(),
                windows.v_l[k].min() < 0.5,
            )
        )
    return np.asarray(rows, dtype=float).reshape(-1, len(IMPACT_COLUMNS))


@dataclass(frozen=True)
class PartA:
    """Part A's replays: the humans and every model on the same held-out windows.

    Attributes
    ----------
    windows : CarFollowingWindows
        The held-out windows evaluated (``W``, once each).
    labels : ndarray of int64, shape (W,)
        Their held-out indices.
    replicates : int
        Replays of each window per model.
    human : Followers
        The recorded followers.
    models : dict of str to Followers
        Per model, over ``W * replicates`` replays.
    replays : dict of str to ReplayResult
        Per model, the ``W * replicates`` replays themselves (window ``w``'s
        replay ``r`` at row ``r W + w``), for :meth:`take_windows`.
    """

    windows: CarFollowingWindows
    labels: NDArray[np.int64]
    replicates: int
    human: Followers
    models: dict[str, Followers]
    replays: dict[str, ReplayResult]

    def take_windows(self, keep: NDArray[np.bool_], road: Road) -> PartA:
        """The same replays, of the windows ``keep`` (bool, shape (W,)) only.

        ``road`` is the road they were replayed on.
        """
        rows = np.tile(keep, self.replicates)
        windows, labels = self.windows.take(keep), self.labels[keep]
        win = windows.take(np.tile(np.arange(len(windows)), self.replicates))
        replays = {name: r.take(rows) for name, r in self.replays.items()}
        return PartA(
            windows=windows,
            labels=labels,
            replicates=self.replicates,
            human=followers(windows, recorded(windows), road, labels),
            models={
                name: followers(win, r, road, labels[np.arange(len(win)) % len(labels)])
                for name, r in replays.items()
            },
            replays=replays,
        )


def run_part_a(
    net: DriverNet,
    fam: Any,
    windows: CarFollowingWindows,
    labels: NDArray[np.int64],
    *,
    seed: int,
    replicates: int,
    road: Road,
    progress: Progress | None = None,
    guard: BrakeGuard | None = None,
) -> PartA:
    """Replay ``windows`` ``replicates`` times with every model of part A.

    Parameters
    ----------
    net : DriverNet
    fam : FixedCovNormal
        ``xi ~ P0``.
    windows : CarFollowingWindows
        ``W`` held-out windows.
    labels : ndarray of int64, shape (W,)
        Their held-out indices.
    seed : int
        Seeds the ``xi`` draws and the replays' noise.
    replicates : int
        ``R``: every model drives ``W R`` replays.
    road : Road
    progress : callable, optional
        ``progress(model, done, total)``.
    guard : BrakeGuard, optional
        The learned drivers' emergency brake (None: none).

    Returns
    -------
    PartA
    """
    tile = np.tile(np.arange(len(windows)), replicates)
    win, win_labels = windows.take(tile), labels[tile]
    n = len(win)
    drivers: dict[str, Any] = dict(
        learned_drivers(net, fam, n, np.random.default_rng(seed), 2, guard)
    )
    # Car following only: MOBIL would overtake the replayed leader.
    drivers["IDM"] = IDMDriver(
        IDMParams.full((n, 2), **{**IDM_NORMAL, "lane_change_threshold": 1e3}),
        road,
    )
    models, replays = {}, {}
    for done, (name, drv) in enumerate(drivers.items()):
        if progress is not None:
            progress(name, done, len(drivers))
        replays[name] = replay(win, drv, road, seed=seed)
        models[name] = followers(win, replays[name], road, win_labels)
    if progress is not None:
        progress("", len(drivers), len(drivers))
    human = followers(windows, recorded(windows), road, labels)
    return PartA(windows, labels, replicates, human, models, replays)


def _figures(f: Followers) -> dict[str, Any]:
    """Percentiles and rates of one group of followers."""
    out: dict[str, Any] = {
        key: percentiles(f.samples[key]) for key in QUANTITIES
    }  # None where empty
    out |= {
        "vehicle_hours": f.hours,
        "hard_brakes": event_rate(f.hard_brakes, f.hours),
        "lane_changes": event_rate(f.lane_changes, f.hours),
        "collisions": clustered_event_rate(f.collisions_by_window, f.hours),
        "road_departures": event_rate(f.road_departures, f.hours),
        "time_stopped": stopped_fraction(f.samples["speed"]),
    }
    return out


def summarise_part_a(part: PartA) -> dict[str, Any]:
    """Part A's figures, JSON-ready.

    Returns
    -------
    dict
        ``windows``, ``window_s``, ``replicates``; ``human`` and, per model,
        ``models[name]``: per :data:`QUANTITIES` key the percentiles
        ``{"p5", "p10", "p50", "p95"}`` (None without samples) and for models
        ``ks`` and ``w1`` to the humans (``w1`` in the quantity's unit; None
        without samples); ``vehicle_hours``; ``hard_brakes``,
        ``lane_changes``, ``collisions`` and ``road_departures`` as ``count``,
        ``per_hour`` [1/veh-h] and exact Poisson ``ci95``, and for
        ``collisions`` also the interval with windows as clusters
        (:func:`~avrisk.realism.metrics.clustered_event_rate`:
        ``ci95_windows``, ``dispersion``, ``windows``,
        ``windows_with_events``); ``time_stopped``
        (share of speeds < 0.1 m/s); for models ``gap_rmse_m`` and
        ``impacts`` (``columns``: :data:`IMPACT_COLUMNS`, ``rows``).
    """
    human = part.human
    models = {}
    for name, f in part.models.items():
        fig = _figures(f)
        for key in QUANTITIES:
            distance = ks_w1(f.samples[key], human.samples[key])
            if fig[key] is not None and distance is not None:
                fig[key] |= {"ks": distance[0], "w1": distance[1]}
        fig["gap_rmse_m"] = f.gap_rmse
        fig["impacts"] = {
            "columns": list(IMPACT_COLUMNS),
            "rows": f.impacts.tolist(),
        }
        models[name] = fig
    return {
        "windows": len(part.windows),
        "window_s": part.windows.n_steps * DT,
        "replicates": part.replicates,
        "human": _figures(human),
        "models": models,
    }
