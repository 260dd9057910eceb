"""Demonstrations from our simulator: lane-keeping students among IDM+MOBIL traffic.

Random multi-lane highway scenes (:func:`random_highway_scenes`) show what
the NGSIM pairs lack (their files hold only a follower and its leader):
neighbours in other lanes and vehicles cutting in. Half of the vehicles of
every scene are "students" (:func:`split_students`) that keep their lane
(MOBIL switched off), and only they are recorded (:class:`RecordingDriver`);
the others are IDM+MOBIL "background" drivers that change lanes around them.
:func:`record_student_rollouts` runs the scenes and collects the students'
rows; :func:`simulated_demonstrations` records lane-keeping IDM students, and
:func:`avrisk.learning.imitation.dagger.dagger_demonstrations` learners labelled by IDM.

These demonstrations are *not human*: they teach the network the IDM model's
lane keeping and reactions. Lane changes are *not* demonstrated: a unimodal
Gaussian policy of the current state cannot represent a discrete lane-change
decision (trained on MOBIL's lane changes it drifted half-way to the next lane
and sideswiped the vehicles it was passing).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.features import N_FEATURES, features_from_observation
from avrisk.agents.idm import IDMDriver, IDMParams
from avrisk.learning.imitation.demonstrations import (
    SOURCE_IDM,
    Demonstrations,
    observing_simulator,
)
from avrisk.sim import Road, VehicleState
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = [
    "NO_LANE_CHANGE",
    "RecordingDriver",
    "random_highway_scenes",
    "record_student_rollouts",
    "simulated_demonstrations",
    "split_students",
]

#: A MOBIL incentive threshold that never triggers a lane change [m/s^2].
NO_LANE_CHANGE = 1e3


class RecordingDriver:
    """An actor that records what its students see and what it does.

    Every ``every`` steps it stores the driver features of all vehicles, the
    actions and which vehicles are usable rows: students, not overlapping
    anyone, in a rollout whose ego has not crashed (numpy, on the CPU).

    Parameters
    ----------
    inner : Actor
        Controls every vehicle; its actions are the recorded labels.
    student : Tensor of bool, shape (B, A)
        Vehicles whose rows are kept.
    every : int, default=1
        Record every this many steps.
    """

    def __init__(self, inner: Any, student: torch.Tensor, every: int = 1) -> None:
        self.inner = inner
        self.controlled = inner.controlled
        self.noise = inner.noise
        self.student = student
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
        self.record(obs, action)
        return action, state

    def record(self, obs: Observation, label: Action) -> None:
        """Store the features and ``label`` of a step (every ``every`` steps)."""
        if obs.step % self.every != 0:
            return
        self.features.append(features_from_observation(obs).float().cpu().numpy())
        self.accel.append(label.accel.float().cpu().numpy())
        self.steer.append(label.steer.float().cpu().numpy())
        # A crashed ego freezes its rollout: drop it; drop anyone overlapping.
        frozen = obs.collided[:, :1].expand_as(obs.collided)
        usable = ~(obs.collided | frozen) & self.student
        self.usable.append(usable.cpu().numpy())

    def demonstrations(self, accel_weight: float, first_episode: int) -> Demonstrations:
        """The recorded students' features and labels.

        Parameters
        ----------
        accel_weight : float
            Weight of the (non-human) acceleration labels (steering weighs 1).
        first_episode : int
            Vehicle ``a`` of rollout ``b`` is episode ``first_episode + b A + a``.

        Returns
        -------
        Demonstrations
            Source ``SOURCE_IDM``.
        """
        feats = np.stack(self.features, 1)  # (B, T', A, F)
        usable = np.stack(self.usable, 1)
        b, _, a = usable.shape
        ids = first_episode + np.arange(b)[:, None] * a + np.arange(a)
        ids = np.broadcast_to(ids[:, None, :], usable.shape)
        m = usable.reshape(-1)
        n = int(m.sum())
        return Demonstrations(
            features=feats.reshape(-1, N_FEATURES)[m],
            accel=np.stack(self.accel, 1).reshape(-1)[m],
            steer=np.stack(self.steer, 1).reshape(-1)[m],
            accel_weight=np.full(n, accel_weight, np.float32),
            steer_weight=np.ones(n, np.float32),
            episode=ids.reshape(-1)[m].astype(np.int64),
            source=np.full(n, SOURCE_IDM, np.int8),
        )


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


def record_student_rollouts(
    recorder: Callable[[IDMParams, torch.Tensor], RecordingDriver],
    n_rollouts: int,
    seed: int,
    *,
    road: Road,
    n_vehicles: int,
    horizon: float,
    accel_weight: float,
    episode_offset: int,
    batch: int,
    rollout_seed_offset: int = 0,
) -> Demonstrations:
    """The students' rows of random highway scenes, driven and labelled by ``recorder``.

    Parameters
    ----------
    recorder : callable
        ``recorder(params, student)`` returns the recording driver of a batch
        of scenes, given its IDM+MOBIL parameters (students' lane changes
        switched off) and its students (:func:`split_students`).
    n_rollouts : int
        Random scenes (:func:`random_highway_scenes`).
    seed : int
        Seeds the scene generator.
    road : Road
    n_vehicles : int
    horizon : float
        [s].
    accel_weight : float
        Weight of the acceleration labels; steering weighs 1.
    episode_offset : int
        Episode ids are ``episode_offset + rollout * n_vehicles + vehicle``.
    batch : int
        Rollouts per simulator call.
    rollout_seed_offset : int, default=0
        Rollout ``r`` is simulated with seed ``rollout_seed_offset + r``.

    Returns
    -------
    Demonstrations
        Every student of every recorded step that is not overlapping another.
    """
    rng = np.random.default_rng(seed)
    sim = observing_simulator(road, horizon)
    parts = []
    for start in range(0, n_rollouts, batch):
        b = min(batch, n_rollouts - start)
        initial, params = random_highway_scenes(b, n_vehicles, road, rng)
        params, student = split_students(params, rng)
        rec = recorder(params, torch.as_tensor(student))
        seeds = torch.as_tensor(
            rollout_seed_offset + start + np.arange(b), dtype=torch.int64
        )
        sim.run(initial, [rec], seeds)
        parts.append(
            rec.demonstrations(accel_weight, episode_offset + start * n_vehicles)
        )
    return Demonstrations.concat(parts)


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
    return record_student_rollouts(
        lambda params, student: RecordingDriver(
            IDMDriver(params, road), student, every=every
        ),
        n_rollouts,
        seed,
        road=road,
        n_vehicles=n_vehicles,
        horizon=horizon,
        accel_weight=accel_weight,
        episode_offset=episode_offset,
        batch=batch,
    )
