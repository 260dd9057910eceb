"""Demonstrations for behaviour cloning: (features, action) pairs with weights.

Where the demonstrations come from
----------------------------------
* **NGSIM I-80 car-following pairs** (:func:`i80_pair_demonstrations`):
  human *longitudinal* behaviour behind a leader. No lateral data, so the
  steering target is missing (weight 0), the follower sits on its lane centre,
  and the lane is the source's lane where it has one (else a fixed pseudo-
  random lane per pair).
* **NGSIM I-80 pairs with lateral positions**
  (:func:`lateral_pair_demonstrations`): human longitudinal *and* lane-keeping
  behaviour (no lane changes: the pairs are single-lane episodes).
* **Our own simulator with IDM drivers** (:func:`simulated_demonstrations`):
  multi-lane traffic, neighbours in other lanes and vehicles cutting in,
  which the NGSIM pairs lack (their files hold only a follower and its
  leader). These demonstrations are *not human*: they teach the network the
  IDM model's lane keeping and reactions; their acceleration targets carry a
  lower weight than the human ones.

Lane changes are *not* demonstrated. Half of the simulated vehicles are
"students": IDM drivers that keep their lane (MOBIL switched off), and only
they are recorded; the others are IDM+MOBIL "background" drivers that change
lanes around them. A unimodal Gaussian policy of the current state cannot
represent a discrete lane-change decision: trained on MOBIL's lane changes it
drifted half-way to the next lane and sideswiped the vehicles it was passing.

One code path for features
--------------------------
A data sample becomes a two-vehicle scene (follower, and its leader ahead in
the same lane) on the scenario road, and its features come from the
simulator's own observation (:meth:`avrisk.sim.Simulator.observe`) through
:func:`avrisk.agents.drivers.features.features_from_observation`: exactly the
code that produces the network's inputs in closed loop. The only difference is
what is in the scene: the NGSIM files have no other neighbours, so the
lidar's side beams see only the road edges.

Action targets are in the simulator's conventions: acceleration is the forward
difference of speed ``(v[t+1] - v[t]) / dt`` [m/s^2] (how the simulator applies
it over a step); steering [rad] is the front-wheel angle of the kinematic
bicycle (:mod:`avrisk.sim.dynamics`) that turns the heading from ``t`` to
``t+1``, from the lateral track smoothed over about a second.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from avrisk.agents.drivers.features import (
    N_BEAMS,
    N_FEATURES,
    features_from_observation,
)
from avrisk.agents.idm import IDMDriver, IDMParams
from avrisk.learning.ngsim import (
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
    "DEFAULT_WIDTH",
    "LIDAR_RANGE",
    "LaneCentres",
    "SOURCE_I80",
    "SOURCE_I80_LATERAL",
    "SOURCE_IDM",
    "SOURCE_NAMES",
    "Demonstrations",
    "RecordingDriver",
    "car_following_features",
    "i80_pair_demonstrations",
    "lateral_pair_demonstrations",
    "lateral_tracks",
    "observing_simulator",
    "random_highway_scenes",
    "simulated_demonstrations",
    "split_students",
    "steer_from_heading",
]

SOURCE_I80, SOURCE_I80_LATERAL, SOURCE_IDM = 0, 1, 2
SOURCE_NAMES = {
    SOURCE_I80: "ngsim_i80_pairs",
    SOURCE_I80_LATERAL: "ngsim_i80_lateral",
    SOURCE_IDM: "sim_idm_mobil",
}
#: Lidar range of the driver features [m] (the scenario default).
LIDAR_RANGE = 50.0
#: Width of a vehicle whose width the data do not give [m].
DEFAULT_WIDTH = 1.9
#: Smoothing of lateral tracks before differentiating (Gaussian sigma) [s].
LATERAL_SMOOTHING = 1.0
#: Wheelbase over length, as in the simulator's default bicycle [-].
WHEELBASE_FRACTION = 0.6


@dataclass(frozen=True)
class Demonstrations:
    """Behaviour-cloning samples; every field has leading length ``N``.

    Attributes
    ----------
    features : ndarray of float32, shape (N, N_FEATURES)
        Driver-network inputs (:mod:`avrisk.agents.drivers.features`).
    accel : ndarray of float32, shape (N,)
        Target acceleration [m/s^2].
    steer : ndarray of float32, shape (N,)
        Target front-wheel angle [rad].
    accel_weight, steer_weight : ndarray of float32, shape (N,)
        Loss weight of each target [-]; 0 where the target is unknown.
    episode : ndarray of int64, shape (N,)
        Trajectory id, unique across sources: the unit of bootstrap resampling.
    source : ndarray of int8, shape (N,)
        :data:`SOURCE_NAMES` key.
    """

    features: NDArray[np.float32]
    accel: NDArray[np.float32]
    steer: NDArray[np.float32]
    accel_weight: NDArray[np.float32]
    steer_weight: NDArray[np.float32]
    episode: NDArray[np.int64]
    source: NDArray[np.int8]

    def __post_init__(self) -> None:
        n = len(self.accel)
        if self.features.shape != (n, N_FEATURES):
            raise ValueError(
                f"features must have shape ({n}, {N_FEATURES}); got "
                f"{self.features.shape}"
            )
        for f in dataclasses.fields(self):
            if len(getattr(self, f.name)) != n:
                raise ValueError(f"Demonstrations.{f.name} must have length {n}")

    def __len__(self) -> int:
        return len(self.accel)

    def take(self, index: Any) -> Demonstrations:
        """Rows ``index`` (mask, slice or integer array)."""
        return dataclasses.replace(
            self,
            **{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)},
        )

    @classmethod
    def concat(cls, parts: Sequence[Demonstrations]) -> Demonstrations:
        """Stack several sets row-wise."""
        return cls(
            **{
                f.name: np.concatenate([getattr(p, f.name) for p in parts])
                for f in dataclasses.fields(cls)
            }
        )

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (no pickle)."""
        np.savez(
            Path(path),
            **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)},
        )

    @classmethod
    def load(cls, path: str | Path) -> Demonstrations:
        """Read a file written by :meth:`save`."""
        with np.load(Path(path), allow_pickle=False) as z:
            return cls(**{f.name: z[f.name] for f in dataclasses.fields(cls)})

    def summary(self) -> dict[str, dict[str, float]]:
        """Rows, episodes and weighted target counts per source."""
        out = {}
        for code, name in SOURCE_NAMES.items():
            m = self.source == code
            if m.any():
                out[name] = {
                    "rows": int(m.sum()),
                    "episodes": int(np.unique(self.episode[m]).size),
                    "accel_targets": float(self.accel_weight[m].sum()),
                    "steer_targets": float(self.steer_weight[m].sum()),
                }
        return out


def observing_simulator(road: Road, horizon: float = SimConfig.horizon) -> Simulator:
    """A simulator whose observations carry the driver network's lidar.

    ``N_BEAMS`` beams of ``LIDAR_RANGE`` m, as the features expect; one TTC ray,
    since demonstrations never read the safety measure. ``horizon`` in s.
    """
    config = SimConfig(horizon=horizon, n_lidar_beams=N_BEAMS, lidar_range=LIDAR_RANGE)
    return Simulator(road, config, measure=MinTTC(n_rays=1))


def car_following_features(
    *,
    speed: NDArray[Any],
    leader_speed: NDArray[Any],
    gap: NDArray[Any],
    length: NDArray[Any],
    width: NDArray[Any],
    leader_length: NDArray[Any],
    leader_width: NDArray[Any],
    lane: NDArray[Any],
    lateral_offset: NDArray[Any],
    heading_offset: NDArray[Any],
    road: Road,
    chunk: int = 16384,
) -> NDArray[np.float32]:
    """Driver features of followers in two-vehicle scenes, via the simulator.

    The follower's centre is at ``x = 0`` in ``lane``, ``lateral_offset`` from
    its centre line, heading ``heading_offset``; the leader is on the same
    lane's centre line, heading along the road, ``gap`` ahead bumper to bumper.

    Parameters
    ----------
    speed, leader_speed : ndarray of shape (N,)
        [m/s].
    gap : ndarray of shape (N,)
        Follower front to leader rear [m].
    length, width, leader_length, leader_width : ndarray of shape (N,)
        [m].
    lane : ndarray of int, shape (N,)
        avrisk lane index (0 = rightmost) on ``road``.
    lateral_offset : ndarray of shape (N,)
        [m], positive to the left.
    heading_offset : ndarray of shape (N,)
        [rad], counter-clockwise.
    road : Road
    chunk : int, default=16384
        Scenes observed per simulator call (memory).

    Returns
    -------
    ndarray of float32, shape (N, N_FEATURES)
    """
    sim = observing_simulator(road)
    centre = (np.asarray(lane, np.float64) + 0.5) * road.lane_width
    zeros = np.zeros_like(centre)
    leader_x = (
        0.5 * np.asarray(length) + np.asarray(gap) + 0.5 * np.asarray(leader_length)
    )
    rows = np.stack(
        [
            np.stack(
                [zeros, centre + lateral_offset, heading_offset, speed, length, width],
                -1,
            ),
            np.stack(
                [leader_x, centre, zeros, leader_speed, leader_length, leader_width], -1
            ),
        ],
        axis=1,
    )  # (N, 2, 6)
    out = np.empty((len(centre), N_FEATURES), np.float32)
    for s in range(0, len(centre), chunk):
        state = VehicleState.from_rows(rows[s : s + chunk].tolist())
        seeds = torch.zeros(state.batch_size, dtype=torch.int64)
        obs = sim.observe(state, seeds)
        out[s : s + chunk] = features_from_observation(obs)[:, 0].numpy()
    return out


def _forward_accel(
    speed: NDArray[Any], starts: NDArray[Any], ends: NDArray[Any], dt: float
):
    """Forward-difference acceleration and a mask of rows that have a next row."""
    accel = np.zeros_like(speed)
    valid = np.zeros(speed.shape, bool)
    for s, e in zip(starts, ends, strict=True):
        accel[s : e - 1] = np.diff(speed[s:e]) / dt
        valid[s : e - 1] = True
    return accel, valid


def steer_from_heading(
    heading: NDArray[Any], speed: NDArray[Any], length: NDArray[Any], dt: float
) -> NDArray[np.float64]:
    """Front-wheel angle that turns ``heading[t]`` into ``heading[t+1]``.

    Inverse of the simulator's kinematic bicycle (:mod:`avrisk.sim.dynamics`):
    ``dpsi = v sin(beta) dt / l_r`` with ``l_r = 0.3 length`` and
    ``tan(steer) = 2 tan(beta)``.

    Parameters
    ----------
    heading : ndarray of shape (T,)
        [rad].
    speed : ndarray of shape (T,)
        [m/s].
    length : ndarray of shape (T,) or float
        [m].
    dt : float
        [s].

    Returns
    -------
    ndarray of shape (T,)
        [rad]; the last entry repeats the one before (no next heading).

    Examples
    --------
    >>> import numpy as np
    >>> psi = np.array([0.0, 0.01])   # 0.01 rad in 0.1 s at 10 m/s, l = 4 m
    >>> round(float(steer_from_heading(psi, np.full(2, 10.0), 4.0, 0.1)[0]), 4)
    0.024
    """
    if len(heading) < 2:
        return np.zeros(len(heading))
    dpsi = np.diff(heading)
    v = np.maximum(np.asarray(speed, np.float64)[:-1], 0.5)
    l_r = 0.5 * WHEELBASE_FRACTION * np.broadcast_to(length, heading.shape)[:-1]
    sin_beta = np.clip(dpsi * l_r / (v * dt), -0.99, 0.99)
    tan_beta = sin_beta / np.sqrt(1.0 - sin_beta**2)
    steer = np.arctan(2.0 * tan_beta)
    return np.r_[steer, steer[-1]]


def _pseudo_lane(key: str, n_lanes: int) -> int:
    return zlib.crc32(key.encode()) % n_lanes


def i80_pair_demonstrations(
    pairs: CarFollowingPairs,
    road: Road,
    *,
    episode_offset: int = 0,
    dt: float = 0.1,
    follower_length: float | None = None,
) -> Demonstrations:
    """Longitudinal demonstrations from the I-80 car-following pairs.

    Parameters
    ----------
    pairs : CarFollowingPairs
        Rows sorted by pair and time (as loaded).
    road : Road
        The road the scenes are placed on (``n_lanes >= 6`` keeps the NGSIM
        lane; otherwise lanes are folded onto the road).
    episode_offset : int, default=0
        Added to the pair index to make episode ids unique across sources.
    dt : float, default=0.1
        Sampling period of the data [s].
    follower_length : float, optional
        Follower length [m] (the file gives only leaders'); default the median
        leader length.

    Returns
    -------
    Demonstrations
        One row per sample that has a successor; steering weight 0.
    """
    starts, ends = episode_bounds(pairs.pair_id)
    accel, valid = _forward_accel(pairs.v_follower, starts, ends, dt)
    p = pairs.take(valid)
    accel = accel[valid]
    n = len(p)
    length = (
        float(np.median(pairs.leader_length))
        if follower_length is None
        else follower_length
    )
    lane = np.empty(n, np.int64)
    episode = np.empty(n, np.int64)
    s2, e2 = episode_bounds(p.pair_id)
    for k, (s, e) in enumerate(zip(s2, e2, strict=True)):
        ngsim_lane = int(p.lane[s])
        if 1 <= ngsim_lane <= I80_N_LANES:
            lane[s:e] = min(I80_N_LANES - ngsim_lane, road.n_lanes - 1)
        else:
            lane[s:e] = _pseudo_lane(f"i80-{p.pair_id[s]}", road.n_lanes)
        episode[s:e] = episode_offset + k
    feats = car_following_features(
        speed=p.v_follower,
        leader_speed=p.v_leader,
        gap=p.gap,
        length=np.full(n, length),
        width=np.full(n, DEFAULT_WIDTH),
        leader_length=p.leader_length,
        leader_width=np.full(n, DEFAULT_WIDTH),
        lane=lane,
        lateral_offset=np.zeros(n),
        heading_offset=np.zeros(n),
        road=road,
    )
    return Demonstrations(
        features=feats,
        accel=accel.astype(np.float32),
        steer=np.zeros(n, np.float32),
        accel_weight=np.ones(n, np.float32),
        steer_weight=np.zeros(n, np.float32),
        episode=episode,
        source=np.full(n, SOURCE_I80, np.int8),
    )


@dataclass(frozen=True)
class LaneCentres:
    """Centre line of each NGSIM lane as a function of the position along the road.

    The lanes of the lateral I-80 file are not straight in its frame: their
    median lateral position wanders by about 0.6 m over the 500 m section.
    Offsets measured from a constant centre would carry that as a systematic
    heading and steering; offsets from this profile do not.

    Attributes
    ----------
    x : ndarray of shape (K,)
        Bin centres along the road [m].
    lanes : tuple of int
        NGSIM lanes, in the order of the rows of ``centre``.
    centre : ndarray of shape (L, K)
        Median lateral position (``Local_X``) of each lane in each bin [m].
    """

    x: NDArray[np.float64]
    lanes: tuple[int, ...]
    centre: NDArray[np.float64]

    @classmethod
    def fit(cls, lateral: LateralPairs, bin_width: float = 25.0) -> LaneCentres:
        """Medians per lane and ``bin_width`` [m] bin (empty bins interpolated)."""
        edges = np.arange(
            np.floor(lateral.x.min()), lateral.x.max() + bin_width, bin_width
        )
        mids = 0.5 * (edges[1:] + edges[:-1])
        lanes = tuple(int(k) for k in np.unique(lateral.lane))
        rows = []
        for k in lanes:
            m = lateral.lane == k
            idx = np.digitize(lateral.x[m], edges) - 1
            med = np.array(
                [
                    np.median(lateral.lateral[m][idx == b])
                    if (idx == b).any()
                    else np.nan
                    for b in range(len(mids))
                ]
            )
            ok = ~np.isnan(med)
            rows.append(np.interp(mids, mids[ok], med[ok]))
        return cls(x=mids, lanes=lanes, centre=np.array(rows))

    def __call__(self, lane: NDArray[Any], x: NDArray[Any]) -> NDArray[np.float64]:
        """Centre line [m] of ``lane`` at ``x``, arrays of shape (N,)."""
        out = np.empty(len(lane))
        for row, k in enumerate(self.lanes):
            m = lane == k
            out[m] = np.interp(x[m], self.x, self.centre[row])
        unknown = ~np.isin(lane, self.lanes)
        if unknown.any():
            raise ValueError(f"no centre line for lanes {np.unique(lane[unknown])}")
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the profile per lane)."""
        return {
            "x_m": self.x.round(2).tolist(),
            **{
                str(k): self.centre[i].round(3).tolist()
                for i, k in enumerate(self.lanes)
            },
        }


def lateral_tracks(
    lateral: LateralPairs, centres: LaneCentres, dt: float = 0.1
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Smoothed lateral offset, heading offset and steering of every row.

    Parameters
    ----------
    lateral : LateralPairs
    centres : LaneCentres
        Lane centre lines (:meth:`LaneCentres.fit`).
    dt : float, default=0.1
        [s].

    Returns
    -------
    offset : ndarray of shape (N,)
        Lateral offset from the lane centre [m], positive to the left.
    heading : ndarray of shape (N,)
        Heading relative to the lane [rad], counter-clockwise.
    steer : ndarray of shape (N,)
        Front-wheel angle [rad] (:func:`steer_from_heading`).
    """
    y = -(lateral.lateral - centres(lateral.lane, lateral.x))  # avrisk: to the left
    offset = np.empty_like(y)
    heading = np.empty_like(y)
    steer = np.empty_like(y)
    sigma = LATERAL_SMOOTHING / dt
    starts, ends = episode_bounds(lateral.pair_id)
    for s, e in zip(starts, ends, strict=True):
        ys = gaussian_filter1d(y[s:e], sigma, mode="nearest")
        v = lateral.speed[s:e]
        vy = np.gradient(ys, dt) if e - s > 1 else np.zeros(e - s)
        psi = np.arctan2(vy, np.maximum(v, 0.5))
        offset[s:e] = ys
        heading[s:e] = psi
        steer[s:e] = steer_from_heading(psi, v, lateral.length[s:e], dt)
    return offset, heading, steer


def lateral_pair_demonstrations(
    lateral: LateralPairs,
    road: Road,
    *,
    centres: LaneCentres | None = None,
    episode_offset: int = 0,
    dt: float = 0.1,
) -> Demonstrations:
    """Longitudinal and lane-keeping demonstrations from the lateral I-80 pairs.

    Parameters
    ----------
    lateral : LateralPairs
    road : Road
    centres : LaneCentres, optional
        Lane centre lines; default fitted to ``lateral``.
    episode_offset : int, default=0
    dt : float, default=0.1
        [s].

    Returns
    -------
    Demonstrations
        One row per sample with a successor; both targets weighted 1.
    """
    centres = LaneCentres.fit(lateral) if centres is None else centres
    offset, heading, steer = lateral_tracks(lateral, centres, dt)
    starts, ends = episode_bounds(lateral.pair_id)
    accel, valid = _forward_accel(lateral.speed, starts, ends, dt)
    episode = np.empty(len(lateral), np.int64)
    for k, (s, e) in enumerate(zip(starts, ends, strict=True)):
        episode[s:e] = episode_offset + k
    lane = np.minimum(I80_N_LANES - lateral.lane, road.n_lanes - 1)
    feats = car_following_features(
        speed=lateral.speed[valid],
        leader_speed=lateral.leader_speed[valid],
        gap=lateral.gap[valid],
        length=lateral.length[valid],
        width=lateral.width[valid],
        leader_length=lateral.leader_length[valid],
        leader_width=lateral.leader_width[valid],
        lane=lane[valid],
        lateral_offset=offset[valid],
        heading_offset=heading[valid],
        road=road,
    )
    n = int(valid.sum())
    return Demonstrations(
        features=feats,
        accel=accel[valid].astype(np.float32),
        steer=steer[valid].astype(np.float32),
        accel_weight=np.ones(n, np.float32),
        steer_weight=np.ones(n, np.float32),
        episode=episode[valid],
        source=np.full(n, SOURCE_I80_LATERAL, np.int8),
    )


class RecordingDriver:
    """An actor that records what an inner actor sees and does.

    Every ``every`` steps it stores the driver features of all vehicles, their
    actions and their ``collided`` flags (numpy, on the CPU).

    Parameters
    ----------
    inner : Actor
        Controls every vehicle.
    every : int, default=1
        Record every this many steps.
    """

    def __init__(self, inner: Any, every: int = 1) -> None:
        self.inner = inner
        self.controlled = inner.controlled
        self.noise = inner.noise
        self.every = every
        self.features: list[NDArray[np.float32]] = []
        self.accel: list[NDArray[np.float32]] = []
        self.steer: list[NDArray[np.float32]] = []
        self.usable: list[NDArray[np.bool_]] = []

    def init(self, obs: Observation, params: Any) -> Any:
        """The inner driver's initial state."""
        return self.inner.init(obs, params)

    def act(self, obs: Observation, state: Any, noise: Any) -> tuple[Action, Any]:
        """The inner driver's action, recorded."""
        action, state = self.inner.act(obs, state, noise)
        if obs.step % self.every == 0:
            self.features.append(features_from_observation(obs).float().cpu().numpy())
            self.accel.append(action.accel.float().cpu().numpy())
            self.steer.append(action.steer.float().cpu().numpy())
            # A crashed ego freezes its rollout: drop it; drop anyone overlapping.
            frozen = obs.collided[:, :1].expand_as(obs.collided)
            self.usable.append((~(obs.collided | frozen)).cpu().numpy())
        return action, state


def random_highway_scenes(
    n_rollouts: int,
    n_vehicles: int,
    road: Road,
    rng: np.random.Generator,
) -> tuple[VehicleState, IDMParams]:
    """Random multi-lane traffic with heterogeneous IDM+MOBIL drivers.

    Vehicles are spread over ``[0, 25 A]`` m in random lanes with at least 5 m
    between bumpers in a lane; speeds U(3, 30) m/s; lateral offsets
    U(-0.5, 0.5) m and headings U(-3, 3) deg so that lane keeping is
    demonstrated too.

    Parameters
    ----------
    n_rollouts, n_vehicles : int
        ``B`` and ``A``.
    road : Road
    rng : numpy.random.Generator

    Returns
    -------
    initial : VehicleState
        Fields of shape (B, A).
    params : IDMParams
        Fields of shape (B, A).
    """
    b, a = n_rollouts, n_vehicles
    length = rng.choice(
        [4.3, 4.8, 5.2, 6.0, 12.0], size=(b, a), p=[0.3, 0.35, 0.2, 0.1, 0.05]
    )
    width = np.where(length > 8, 2.5, rng.uniform(1.7, 2.0, (b, a)))
    lane = rng.integers(0, road.n_lanes, (b, a))
    x = np.zeros((b, a))
    extent = 25.0 * a
    for i in range(b):
        for _ in range(200):
            xi = rng.uniform(0.0, extent, a)
            same = lane[i, :, None] == lane[i, None, :]
            dist = np.abs(xi[:, None] - xi[None, :]) - 0.5 * (
                length[i, :, None] + length[i, None, :]
            )
            np.fill_diagonal(same, False)
            if not (same & (dist < 5.0)).any():
                break
        x[i] = xi
    y = (lane + 0.5) * road.lane_width + rng.uniform(-0.5, 0.5, (b, a))
    heading = np.deg2rad(rng.uniform(-3.0, 3.0, (b, a)))
    speed = rng.uniform(3.0, 30.0, (b, a))
    initial = VehicleState(
        *(
            torch.as_tensor(v, dtype=torch.float32)
            for v in (x, y, heading, speed, length, width)
        )
    )

    def u(lo: float, hi: float) -> torch.Tensor:
        return torch.as_tensor(rng.uniform(lo, hi, (b, a)), dtype=torch.float32)

    params = IDMParams(
        desired_speed=u(12.0, 33.0),
        time_headway=u(0.8, 2.0),
        min_gap=u(1.0, 3.0),
        max_accel=u(0.8, 2.5),
        comfort_decel=u(1.5, 3.5),
        politeness=u(0.0, 0.5),
        lane_change_threshold=u(0.05, 0.5),
    )
    return initial, params


#: A MOBIL incentive threshold that never triggers a lane change [m/s^2].
NO_LANE_CHANGE = 1e3


def split_students(
    params: IDMParams, rng: np.random.Generator, fraction: float = 0.5
) -> tuple[IDMParams, NDArray[np.bool_]]:
    """Mark a random fraction of the vehicles as lane-keeping students.

    Parameters
    ----------
    params : IDMParams
        Fields of shape (B, A).
    rng : numpy.random.Generator
    fraction : float, default=0.5
        Probability that a vehicle is a student.

    Returns
    -------
    params : IDMParams
        The students' ``lane_change_threshold`` set to :data:`NO_LANE_CHANGE`.
    student : ndarray of bool, shape (B, A)
    """
    student = rng.random(tuple(params.shape)) < fraction
    mask = torch.as_tensor(student, device=params.lane_change_threshold.device)
    thr = params.lane_change_threshold
    return (
        dataclasses.replace(
            params, lane_change_threshold=torch.where(mask, NO_LANE_CHANGE, thr)
        ),
        student,
    )


def simulated_demonstrations(
    n_rollouts: int,
    seed: int,
    *,
    road: Road | None = None,
    n_vehicles: int = 8,
    horizon: float = 15.0,
    every: int = 2,
    accel_weight: float = 0.25,
    episode_offset: int = 0,
    batch: int = 128,
) -> Demonstrations:
    """Demonstrations by lane-keeping IDM drivers among IDM+MOBIL traffic.

    In every scene half of the vehicles (:func:`split_students`) keep their
    lane and are recorded; the others change lanes around them.

    Parameters
    ----------
    n_rollouts : int
        Random scenes (:func:`random_highway_scenes`).
    seed : int
        Seeds the scene generator.
    road : Road, optional
        Default ``Road()`` (the scenario's 6 x 3.7 m highway).
    n_vehicles : int, default=8
    horizon : float, default=15.0
        [s].
    every : int, default=2
        Keep every this many steps (consecutive steps are nearly duplicates).
    accel_weight : float, default=0.25
        Weight of the (non-human) acceleration targets; steering weighs 1.
    episode_offset : int, default=0
        Episode ids are ``episode_offset + rollout * n_vehicles + vehicle``.
    batch : int, default=128
        Rollouts per simulator call.

    Returns
    -------
    Demonstrations
        Every student of every recorded step that is not overlapping another.
    """
    road = Road() if road is None else road
    rng = np.random.default_rng(seed)
    sim = observing_simulator(road, horizon)
    parts = []
    for start in range(0, n_rollouts, batch):
        b = min(batch, n_rollouts - start)
        initial, params = random_highway_scenes(b, n_vehicles, road, rng)
        params, student = split_students(params, rng)
        rec = RecordingDriver(IDMDriver(params, road), every=every)
        sim.run(initial, [rec], torch.arange(start, start + b, dtype=torch.int64))
        feats = np.stack(rec.features, 1)  # (b, T', A, F)
        usable = np.stack(rec.usable, 1) & student[:, None, :]
        ids = (
            episode_offset
            + (start + np.arange(b))[:, None] * n_vehicles
            + np.arange(n_vehicles)
        )
        ids = np.broadcast_to(ids[:, None, :], usable.shape)
        m = usable.reshape(-1)
        n = int(m.sum())
        parts.append(
            Demonstrations(
                features=feats.reshape(-1, N_FEATURES)[m],
                accel=np.stack(rec.accel, 1).reshape(-1)[m],
                steer=np.stack(rec.steer, 1).reshape(-1)[m],
                accel_weight=np.full(n, accel_weight, np.float32),
                steer_weight=np.ones(n, np.float32),
                episode=ids.reshape(-1)[m].astype(np.int64),
                source=np.full(n, SOURCE_IDM, np.int8),
            )
        )
    return Demonstrations.concat(parts)
