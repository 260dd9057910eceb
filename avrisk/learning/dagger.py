"""DAgger: demonstrations on the states the learned drivers actually visit.

Behaviour cloning trains on the states of the demonstrators; in closed loop
the learned drivers drift into states the demonstrators never showed (off the
lane centre, too close to a leader) and do not know how to recover -- the
covariate shift of Ross and Bagnell (2010), which the paper cites as the
reason for GAIL. DAgger (Ross, Gordon, Bagnell 2011) fixes it by letting the
learner drive and an expert label the visited states::

    for i in 1..K:
        roll out the learned drivers in random highway scenes
        label every visited state with the expert's action
        add the labelled states to the demonstrations; refit

No human can be queried on our simulated states, so the expert here is the
lane-keeping IDM driver (:mod:`avrisk.agents.idm`, MOBIL off), run alongside
the learner with its own memory. As in the behaviour-cloning scenes, half of
the vehicles are learners ("students") and the others are IDM+MOBIL
background traffic that changes lanes around them. The DAgger labels
therefore teach *recovery, lane keeping and reactions as IDM does them*;
human longitudinal behaviour still comes from the NGSIM demonstrations (the
DAgger acceleration labels carry a lower weight).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.features import (
    N_FEATURES,
    features_from_observation,
)
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.idm import IDMDriver, IDMState
from avrisk.learning.demonstrations import (
    SOURCE_IDM,
    Demonstrations,
    observing_simulator,
    random_highway_scenes,
    split_students,
)
from avrisk.learning.replay import CarFollowingWindows, replay
from avrisk.sim import Road
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = ["ExpertLabeller", "dagger_demonstrations", "replay_dagger_demonstrations"]


class ExpertLabeller:
    """An actor of every vehicle: learners act, the expert's actions are recorded.

    Parameters
    ----------
    learner : Actor
        Drives the students (its actions go to the simulator).
    expert : IDMDriver
        Labels the students' states and drives everyone else (it controls
        every vehicle).
    student : Tensor of bool, shape (B, A)
        Vehicles driven by the learner (and recorded).
    every : int, default=2
        Record every this many steps.
    """

    def __init__(
        self, learner: Any, expert: IDMDriver, student: torch.Tensor, every: int = 2
    ) -> None:
        self.learner = learner
        self.expert = expert
        self.controlled = expert.controlled
        self.noise = learner.noise
        self.student = student
        self.every = every
        self.features: list[NDArray[np.float32]] = []
        self.accel: list[NDArray[np.float32]] = []
        self.steer: list[NDArray[np.float32]] = []
        self.usable: list[NDArray[np.bool_]] = []

    def init(self, obs: Observation, params: Any) -> tuple[Any, IDMState]:
        """Both models' initial states (``params`` are the learner's)."""
        return self.learner.init(obs, params), self.expert.init(obs, None)

    def act(
        self, obs: Observation, state: tuple[Any, IDMState], noise: Any
    ) -> tuple[Action, Any]:
        """Students follow the learner, others the expert; labels are stored."""
        learner_state, expert_state = state
        mine, learner_state = self.learner.act(obs, learner_state, noise)
        label, expert_state = self.expert.act(obs, expert_state, None)
        action = Action(
            accel=torch.where(self.student, mine.accel, label.accel),
            steer=torch.where(self.student, mine.steer, label.steer),
        )
        if obs.step % self.every == 0:
            self.features.append(features_from_observation(obs).float().cpu().numpy())
            self.accel.append(label.accel.float().cpu().numpy())
            self.steer.append(label.steer.float().cpu().numpy())
            frozen = obs.collided[:, :1].expand_as(obs.collided)
            usable = ~(obs.collided | frozen) & self.student
            self.usable.append(usable.cpu().numpy())
        return action, (learner_state, expert_state)

    def demonstrations(self, accel_weight: float, first_episode: int) -> Demonstrations:
        """The recorded students' features and expert labels.

        Parameters
        ----------
        accel_weight : float
            Weight of the expert's acceleration labels (steering weighs 1).
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


def dagger_demonstrations(
    net: DriverNet,
    n_rollouts: int,
    seed: int,
    *,
    road: Road | None = None,
    xi: torch.Tensor | None = None,
    n_vehicles: int = 8,
    horizon: float = 15.0,
    every: int = 2,
    accel_weight: float = 0.25,
    stochastic: bool = True,
    episode_offset: int = 0,
    batch: int = 128,
) -> Demonstrations:
    """Expert-labelled states visited by the learned drivers.

    Half of the vehicles of every scene are learners (students, recorded); the
    others are IDM+MOBIL traffic (see
    :func:`~avrisk.learning.demonstrations.split_students`).

    Parameters
    ----------
    net : DriverNet
        The current learner.
    n_rollouts : int
        Random scenes (:func:`~avrisk.learning.demonstrations.random_highway_scenes`).
    seed : int
        Seeds the scenes and the action noise.
    road : Road, optional
        Default ``Road()``.
    xi : Tensor of shape (XI_DIM,), optional
        Learner's last layer; default the network's.
    n_vehicles : int, default=8
    horizon : float, default=15.0
        [s].
    every : int, default=2
        Record every this many steps.
    accel_weight : float, default=0.25
        Weight of the expert's (non-human) acceleration labels.
    stochastic : bool, default=True
        The learner samples its actions (as it will in deployment).
    episode_offset : int, default=0
    batch : int, default=128
        Rollouts per simulator call.

    Returns
    -------
    Demonstrations
        Source ``SOURCE_IDM``: the labels are IDM+MOBIL's.
    """
    road = Road() if road is None else road
    rng = np.random.default_rng(seed)
    sim = observing_simulator(road, horizon)
    parts = []
    for start in range(0, n_rollouts, batch):
        b = min(batch, n_rollouts - start)
        initial, params = random_highway_scenes(b, n_vehicles, road, rng)
        params, student = split_students(params, rng)
        everyone = torch.ones(n_vehicles, dtype=torch.bool)
        learner = LearnedDriver(net, xi, controlled=everyone, stochastic=stochastic)
        rec = ExpertLabeller(
            learner, IDMDriver(params, road), torch.as_tensor(student), every=every
        )
        seeds = torch.as_tensor(
            seed * 1_000_003 + start + np.arange(b), dtype=torch.int64
        )
        sim.run(initial, [rec], seeds)
        first = episode_offset + start * n_vehicles
        parts.append(rec.demonstrations(accel_weight, first))
    return Demonstrations.concat(parts)


def replay_dagger_demonstrations(
    net: DriverNet,
    windows: CarFollowingWindows,
    seed: int,
    *,
    road: Road | None = None,
    every: int = 2,
    accel_weight: float = 0.25,
    stochastic: bool = True,
    episode_offset: int = 0,
) -> Demonstrations:
    """Expert labels on the learner following recorded human leaders.

    The random highway scenes rarely show the slow, close queues of congested
    traffic that dominate NGSIM. Here the learner drives the follower of human
    car-following windows (:func:`avrisk.learning.replay.replay`; the leader
    replays its recorded speed) and a lane-keeping IDM driver with randomised
    parameters labels the states it reaches, so that the learner is also
    taught to recover when it ends up too close to a braking leader.

    Parameters
    ----------
    net : DriverNet
        The current learner.
    windows : CarFollowingWindows
        Training windows (never evaluation ones).
    seed : int
        Seeds the expert's parameters and the action noise.
    road : Road, optional
        Default ``Road()``.
    every : int, default=2
        Record every this many steps.
    accel_weight : float, default=0.25
        Weight of the expert's acceleration labels.
    stochastic : bool, default=True
        The learner samples its actions.
    episode_offset : int, default=0

    Returns
    -------
    Demonstrations
        The follower's rows only; source ``SOURCE_IDM``.
    """
    road = Road() if road is None else road
    rng = np.random.default_rng(seed)
    n = len(windows)
    _, params = random_highway_scenes(n, 2, road, rng)
    params, _ = split_students(params, rng, fraction=1.0)  # nobody changes lanes
    student = torch.zeros(n, 2, dtype=torch.bool)
    student[:, 0] = True
    everyone = torch.ones(2, dtype=torch.bool)
    learner = LearnedDriver(net, controlled=everyone, stochastic=stochastic)
    rec = ExpertLabeller(learner, IDMDriver(params, road), student, every=every)
    replay(windows, rec, road, seed=seed)
    return rec.demonstrations(accel_weight, episode_offset)
