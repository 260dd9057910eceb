"""More replicates of the levels where their answer is imprecise.

Where ``splitting_is``'s levels answer (*The answer* in
:mod:`avrisk.rare.splitting_importance`), the proposal could not hold what
the particles found, most often many failure regions in many dimensions, and
the answer is as precise as the levels' product. With few particles per
region that product is known only to within a factor of about 2 (ten
regions in ``d = 200`` at 2,500 particles: ``log p`` spread 0.29), and a run
whose interval misses by more than 2x then happens in about one run in a
hundred, with nothing inside the run to mark it (BENCHMARKS.md, "The levels'
bias and their precision").

So a levels' answer is taken to a stated precision, ``PRECISE_LOG_SE``: three
standard errors of ``log p`` within a factor of 2, so that a miss by 2x is a
three-sigma event. While its interval is wider than that, the run adds
replicates of the levels (fresh draws, the first replicates' particles per
level, stages of their own after the moves at ``gamma``), each while the
most it can take, and the final stage after it, stay within the run's
budget, and at most as many as the run planned (the levels' particles at
most doubled: beyond that, raise ``n_particles``). Their products join the
levels' mean; they do not join the proposal, fitted before them. One that
runs out of levels is kept in the record and ends the additions, and the
levels no longer answer (as for any replicate that ran out). The calls they
take are the ones the plan held for levels that reach ``gamma`` in fewer than
``max_levels`` sets: the budget and the progress bar are unchanged.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate, GammaEstimate
from avrisk.rare.splitting import OneReplicate
from avrisk.rare.splitting_levels import Z_CONFIDENCE, levels_estimate
from avrisk.rare.splitting_replicates import ReplicatesState, combined_levels

__all__ = ["PRECISE_LOG_SE", "MoreReplicates", "imprecise", "more_replicates"]

#: The standard error of ``log p`` a levels' answer is taken to: three of them
#: within a factor of 2 (a miss by more than 2x is the exact suite's gross
#: miss, benchmarks/exact_suite.py).
PRECISE_LOG_SE = math.log(2.0) / 3.0


def imprecise(levels: GammaEstimate) -> bool:
    """Whether an estimate's interval is wider than ``PRECISE_LOG_SE`` allows.

    Its upper end over ``p``, on the log scale, beyond ``Z_CONFIDENCE
    PRECISE_LOG_SE`` (the interval is normal or Student's t on ``log p``); an
    estimate of 0 (a bound) is not made more precise by more replicates.
    """
    if levels.p <= 0:
        return False
    return math.log(levels.ci[1] / levels.p) > Z_CONFIDENCE * PRECISE_LOG_SE


class MoreReplicates(NamedTuple):
    """The replicates after the additions, and their levels' estimate.

    Attributes
    ----------
    state : ReplicatesState
        Every replicate, the added ones last.
    own : list of Estimate
        The estimate of each that reached ``gamma``.
    combined : Estimate
        Their mean (:func:`~avrisk.rare.splitting_replicates.combined_levels`).
    n_evals : int
        Calls of ``f`` so far, the additions' included.
    n_stages : int
        Stages used so far (the next addition's first is this one).
    added : int
        Replicates added.
    """

    state: ReplicatesState
    own: list[Estimate]
    combined: Estimate
    n_evals: int
    n_stages: int
    added: int


def more_replicates(
    levels: OneReplicate,
    start: MoreReplicates,
    problem: RareEventProblem,
    context: EstimationContext,
    room: int,
    most: int,
) -> MoreReplicates:
    """Replicates added while the levels' answer is imprecise and fits (module doc).

    Parameters
    ----------
    levels : OneReplicate
        One replicate's levels at the first replicates' particles per level.
    start : MoreReplicates
        The replicates so far (``added`` 0), with the calls and stages used.
    problem, context
        The run's.
    room : int
        The most calls of ``f`` the additions may take in all (the run's
        budget less its calls so far and its final stage).
    most : int
        The most replicates to add (the run's planned number).
    """
    current = start
    n = levels.settings.n_particles
    # its most: every set moved as after correlated chains, where the run may
    bound = levels.settings.levels_bound(n, correlated=True)
    while (
        current.added < most
        and imprecise(current.combined.by_gamma[problem.gamma])
        and current.n_evals - start.n_evals + bound <= room
    ):
        r = levels.init(problem)._replace(
            n_stages=current.n_stages, n_evals=current.n_evals
        )
        while not levels.done(r):
            r, _ = levels.step(r, problem, context)
        s = current.state
        state = ReplicatesState(s.all, r, (*s.sizes, n), s.filled + 1)
        own = current.own
        if not r.exhausted:
            own = [*own, levels_estimate(r, problem, n, genealogy=True)]
        particles = sum(m for _, m in state.reached())
        current = MoreReplicates(
            state,
            own,
            combined_levels(own, problem, particles),
            r.n_evals,
            r.n_stages,
            current.added + 1,
        )
        if r.exhausted:
            break
    return current
