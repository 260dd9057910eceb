"""The safest of several trainings of one recipe, chosen on training data alone.

Trainings of the same recipe that differ only in their seed crash on the
held-out windows very differently (docs/benchmarks-history.md, "The shipped
recipe over training seeds"), and the closed-loop stage's early stopping does not see it
(one replay per validation window). What does: replaying the closed-loop
stage's own validation windows (the share ``validation_fraction`` of the
training windows that the stage held out, drawn with the training's seed)
:data:`REPLICATES` times each with ``xi ~ P0`` and sampled actions, the
leaders' speed changes made :data:`STRESS` times as large
(:func:`~avrisk.learning.training.closed_loop.stressed`): its crash count
ranks the trainings' held-out collisions (BENCHMARKS.md, "Keeping the safest
of several trainings").

:func:`validation_crashes` scores one training; :func:`choose` keeps the one
with the fewest stressed crashes (then the fewest crashes with the leaders as
recorded, then the lowest seed). No held-out window is used.

Examples
--------
>>> a = CandidateScore(seed=0, replays=1704, stressed_crashes=9, crashes=2,
...                    stressed_windows=2)
>>> b = CandidateScore(seed=1, replays=1704, stressed_crashes=30, crashes=21,
...                    stressed_windows=14)
>>> choose([b, a]).seed
0
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import XiPrior
from avrisk.learning.replay import CarFollowingWindows, replay
from avrisk.learning.train_config import ClosedLoopConfig
from avrisk.learning.training.closed_loop import split_windows, stressed
from avrisk.scenario.base_distribution import xi_base_family
from avrisk.sim import Road

__all__ = [
    "REPLICATES",
    "STRESS",
    "CandidateScore",
    "choose",
    "validation_crashes",
]

#: Replays of every validation window per score.
REPLICATES = 8
#: The validation leaders' speed changes are made this many times as large.
STRESS = 1.5


@dataclass(frozen=True)
class CandidateScore:
    """How often one training's drivers crash on its validation windows.

    Attributes
    ----------
    seed : int
        The training's seed.
    replays : int
        Replays of each kind: validation windows x :data:`REPLICATES`.
    stressed_crashes : int
        Crashes with the leaders' speed changes made :data:`STRESS` times as
        large (what :func:`choose` ranks by).
    crashes : int
        Crashes with the leaders as recorded (the tie-break).
    stressed_windows : int
        Validation windows with at least one stressed crash.
    """

    seed: int
    replays: int
    stressed_crashes: int
    crashes: int
    stressed_windows: int


def validation_crashes(
    net: DriverNet,
    prior: XiPrior,
    windows: CarFollowingWindows,
    config: ClosedLoopConfig,
    seed: int,
    *,
    replicates: int = REPLICATES,
    stress: float = STRESS,
    guard: BrakeGuard | None = None,
) -> CandidateScore:
    """Score a training by its crashes on the closed-loop stage's validation windows.

    Parameters
    ----------
    net : DriverNet
    prior : XiPrior
        ``xi ~ N(mu0, Sigma0)``, one draw per replay.
    windows : CarFollowingWindows
        The closed-loop stage's training windows (``window_steps`` long).
    config : ClosedLoopConfig
        Its ``validation_fraction`` chooses the validation windows.
    seed : int
        The training's seed: the same split as its closed-loop stage; it also
        seeds the ``xi`` draws and the actions' noise.
    replicates : int, default=REPLICATES
    stress : float, default=STRESS
        At least 1.
    guard : BrakeGuard, optional
        The drivers' emergency brake (None: the network alone).

    Returns
    -------
    CandidateScore
    """
    if replicates < 1 or stress < 1.0:
        raise ValueError(
            f"need replicates >= 1 and stress >= 1; got {replicates} and {stress}"
        )
    _, val = split_windows(len(windows), config.validation_fraction, seed)
    tiled = windows.take(np.tile(val, replicates))
    fam = xi_base_family(prior)
    xi = torch.as_tensor(
        fam.sample(len(tiled), np.random.default_rng([seed, 1])), dtype=torch.float32
    )
    every = torch.ones(2, dtype=torch.bool)
    driver = LearnedDriver(net, xi, controlled=every, guard=guard)
    crashed = {
        kind: np.asarray(replay(win, driver, Road(), seed=seed).crash)
        for kind, win in (("plain", tiled), ("stressed", stressed(tiled, stress)))
    }
    per_window = crashed["stressed"].reshape(replicates, len(val)).sum(axis=0)
    return CandidateScore(
        seed=seed,
        replays=len(tiled),
        stressed_crashes=int(crashed["stressed"].sum()),
        crashes=int(crashed["plain"].sum()),
        stressed_windows=int(np.count_nonzero(per_window)),
    )


def choose(scores: Sequence[CandidateScore]) -> CandidateScore:
    """The score with the fewest stressed crashes (then crashes, then seed).

    Raises
    ------
    ValueError
        For no scores.
    """
    if not scores:
        raise ValueError("no candidate to choose from")
    return min(scores, key=lambda s: (s.stressed_crashes, s.crashes, s.seed))
