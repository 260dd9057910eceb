"""Demonstrations from the NGSIM I-80 data: human car following and lane keeping.

* **Car-following pairs** (:func:`i80_pair_demonstrations`): human
  *longitudinal* behaviour behind a leader. No lateral data, so the steering
  target is missing (weight 0), the follower sits on its lane centre, and the
  lane is the source's lane where it has one (else a fixed pseudo-random lane
  per pair).
* **Pairs with lateral positions** (:func:`lateral_pair_demonstrations`):
  human longitudinal *and* lane-keeping behaviour (no lane changes: the pairs
  are single-lane episodes), the lateral motion from
  :mod:`avrisk.learning.ngsim.lateral`.

A data sample becomes a two-vehicle scene (follower, and its leader ahead in
the same lane) on the scenario road, observed by the simulator
(:func:`car_following_features`; see :mod:`avrisk.learning.imitation.demonstrations`).
Acceleration targets are the forward difference of speed
``(v[t+1] - v[t]) / dt`` [m/s^2] (how the simulator applies it over a step).
"""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.features import N_FEATURES, features_from_observation
from avrisk.learning.imitation.demonstrations import (
    SOURCE_I80,
    SOURCE_I80_LATERAL,
    Demonstrations,
    observing_simulator,
)
from avrisk.learning.ngsim.lateral import LaneCentres, lateral_tracks
from avrisk.learning.ngsim.samples import (
    DEFAULT_WIDTH,
    I80_N_LANES,
    CarFollowingPairs,
    LateralPairs,
    episode_bounds,
)
from avrisk.sim import Road, VehicleState

__all__ = [
    "car_following_features",
    "i80_pair_demonstrations",
    "lateral_pair_demonstrations",
]


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
