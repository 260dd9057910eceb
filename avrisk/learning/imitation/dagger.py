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
DAgger acceleration labels carry a lower weight). The loop is
:func:`dagger_rounds`, the DAgger stage of
:func:`~avrisk.learning.training.train.train_drivers`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.idm import IDMDriver, IDMState
from avrisk.learning.imitation.behaviour_cloning import behaviour_cloning
from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.imitation.simulated_demonstrations import (
    RecordingDriver,
    random_highway_scenes,
    record_student_rollouts,
    split_students,
)
from avrisk.learning.replay import CarFollowingWindows, replay
from avrisk.learning.train_config import Progress, TrainConfig, TrainEvent
from avrisk.sim import Road
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = [
    "ExpertLabeller",
    "dagger_demonstrations",
    "dagger_rounds",
    "replay_dagger_demonstrations",
]


class ExpertLabeller(RecordingDriver):
    """A recording driver whose students the learner drives; the expert labels them.

    Parameters
    ----------
    learner : Actor
        Drives the students (its actions go to the simulator); its noise is
        the one the simulator draws for this actor.
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
        super().__init__(expert, student, every)
        self.learner = learner
        self.noise = learner.noise

    def init(self, obs: Observation, params: Any) -> tuple[Any, IDMState]:
        """Both models' initial states (``params`` are the learner's)."""
        return self.learner.init(obs, params), self.inner.init(obs, None)

    def act(
        self, obs: Observation, state: tuple[Any, IDMState], noise: Any
    ) -> tuple[Action, Any]:
        """Students follow the learner, others the expert; labels are stored."""
        learner_state, expert_state = state
        mine, learner_state = self.learner.act(obs, learner_state, noise)
        label, expert_state = self.inner.act(obs, expert_state, None)
        action = Action(
            accel=torch.where(self.student, mine.accel, label.accel),
            steer=torch.where(self.student, mine.steer, label.steer),
        )
        self.record(obs, label)
        return action, (learner_state, expert_state)


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
    :func:`~avrisk.learning.imitation.simulated_demonstrations.split_students`).

    Parameters
    ----------
    net : DriverNet
        The current learner.
    n_rollouts : int
        Random scenes
        (:func:`~avrisk.learning.imitation.simulated_demonstrations.random_highway_scenes`).
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
    return record_student_rollouts(
        lambda params, student: ExpertLabeller(
            LearnedDriver(
                net,
                xi,
                controlled=torch.ones(student.shape[1], dtype=torch.bool),
                stochastic=stochastic,
            ),
            IDMDriver(params, road),
            student,
            every=every,
        ),
        n_rollouts,
        seed,
        road=road,
        n_vehicles=n_vehicles,
        horizon=horizon,
        accel_weight=accel_weight,
        episode_offset=episode_offset,
        batch=batch,
        rollout_seed_offset=seed * 1_000_003,
    )


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


def dagger_rounds(
    net: DriverNet,
    train: Demonstrations,
    val: Demonstrations,
    config: TrainConfig,
    seed: int,
    follow: CarFollowingWindows | None = None,
    progress: Progress | None = None,
) -> tuple[Demonstrations, list[dict[str, float]]]:
    """DAgger: ``config.dagger_iters`` rounds of expert labels and refits.

    Every round the learner drives ``config.dagger_rollouts`` random scenes
    (:func:`dagger_demonstrations`) and, with ``follow``,
    ``config.dagger_windows`` of those human windows
    (:func:`replay_dagger_demonstrations`); the labelled states join the
    demonstrations and the network is refitted on all of them
    (:func:`~avrisk.learning.imitation.behaviour_cloning.behaviour_cloning`).

    Parameters
    ----------
    net : DriverNet
        The learner, refitted in place.
    train, val : Demonstrations
        Demonstrations so far, and validation ones.
    config : TrainConfig
    seed : int
    follow : CarFollowingWindows, optional
        Training windows to draw the replayed ones from (each round anew).
    progress : callable, optional
        Receives a ``"dagger"`` :class:`TrainEvent` after every round.

    Returns
    -------
    train : Demonstrations
        ``train`` and every round's labelled states.
    history : list of dict
        Per round: rows added and the last refit epoch's losses.
    """
    history = []
    for k in range(config.dagger_iters):
        visited = dagger_demonstrations(
            net,
            config.dagger_rollouts,
            seed * 1000 + 10 + k,
            accel_weight=config.dagger_accel_weight,
            episode_offset=(100 + k) * 1_000_000,
        )
        if follow is not None:
            replay_seed = seed * 1000 + 500 + k
            followed = replay_dagger_demonstrations(
                net,
                follow.sample(config.dagger_windows, replay_seed),
                replay_seed,
                accel_weight=config.dagger_accel_weight,
                episode_offset=(200 + k) * 1_000_000,
            )
            visited = Demonstrations.concat([visited, followed])
        train = Demonstrations.concat([train, visited])
        refit = behaviour_cloning(
            net,
            train,
            epochs=config.dagger_epochs,
            batch_size=config.batch_size,
            lr=config.dagger_lr,
            weight_decay=config.weight_decay,
            seed=seed + 1 + k,
            val=val,
        )
        row = {"round": float(k + 1), "rows_added": float(len(visited)), **refit[-1]}
        history.append(row)
        if progress is not None:
            progress(TrainEvent("dagger", k + 1, config.dagger_iters, row))
    return train, history
