"""The moves of subset simulation: draws of ``P0`` and pCN chains below a level.

:mod:`avrisk.rare.splitting` states the method; each of its particle sets
after the first is made here, by Markov chains that start from the last set's
survivors and stay below its level (:func:`move_chains`). The first set is
draws of ``P0`` (:func:`draw_p0`, :func:`drawn_more` on a plateau). Every
batch of points is evaluated here (``f`` at standard-normal points, a stage per chunk).

Moves
-----
Chains move in the space of independent standard normals of the base family
(:meth:`~avrisk.rare.families.base.ExponentialFamily.to_standard_normal`):
``X = T^-1(Z)`` with ``Z ~ N(0, I)``. A preconditioned Crank-Nicolson proposal
``z' = sqrt(1 - beta^2) z + beta eps``, ``eps ~ N(0, I)``, is reversible with
respect to ``N(0, I)``, so accepting it iff ``f(T^-1(z')) <= b_l`` leaves ``P0``
conditioned on ``f <= b_l`` invariant, with no density ratio; and its
acceptance does not fall with the dimension. The chains move in lockstep, one
round of proposals at a time; after each round ``beta`` is multiplied by
``exp(ADAPT_GAIN (accepted - TARGET_ACCEPTANCE proposed) / chains)`` (clipped
to ``[MIN_BETA, 1]``), which drives the acceptance rate towards
``TARGET_ACCEPTANCE = 0.3``; ``beta`` carries over from level to level. A chain
that is refused keeps its state (as Metropolis-Hastings does); only when no
chain accepts in ``MAX_ROUNDS_WITHOUT_MOVE`` rounds in a row with ``beta``
already at ``MIN_BETA`` (a step that barely moves: the set below the level has
no volume, or ``f`` jumps) does the run stop with a
:class:`~avrisk.rare.splitting_levels.SplittingError`. With ``n_moves > 1`` a
chain keeps every ``n_moves``-th state only (thinning). Where the chains that
made the last set mixed slowly -- their states' correlation inflated the
variance of its share of survivors more than ``CORRELATED`` times (Au & Beck's
factor, :func:`~avrisk.rare.splitting_levels.chain_correlation`) -- the next
set's chains take ``correlated_moves`` times as many proposals per kept state
(:func:`moves_after`): a chain that barely leaves its seed repeats its seed's
position, not the conditional law's spread, and the levels built on it lose
the mass its seeds did not hold. On the exact suite's problems the factor
stays below about 2.7; on ``highway_rare``, whose event is a thin ridge, it
reaches 3-5 (BENCHMARKS.md).

After the moves at ``gamma``, ``splitting_is`` refreshes the coordinates
its particles do not inform (:func:`refreshed`): each particle proposes
fresh ``N(0, 1)`` draws of them, the rest kept, and keeps the proposal if it
is still below the level. That is pCN with ``beta = 1`` on those coordinates,
reversible with respect to ``N(0, I)`` as any pCN step is, so the
conditional law stays invariant; where ``f`` does not depend on them it is
accepted every time and forgets in one step what the particle's ancestors
left there.

For a seeded (stochastic) ``f`` each proposal has its own seed: the chain
moves on ``(x, seed)``, and a fresh seed is an independence proposal from its
prior, so the move stays reversible.

Seeds and resume
----------------
Every batch of at most :data:`~avrisk.rare.problem.SAMPLE_CHUNK` points is
evaluated through :meth:`EstimationContext.evaluate` as chunk 0 of its own
stage (1, 2, ... in the order of the run; a stage's per-sample seeds depend on
the stage, so no two proposals share one); its random numbers come from
``default_rng([seed, stage])``. The points are functions of the run seed and
of earlier values of ``f`` only: a resumed run asks for the recorded points
again and replays them, and the result does not depend on ``batch_size``.
A failed evaluation's ``f`` is ``+inf``: outside every level, so a failed
proposal is rejected.

References
----------
S. L. Cotter, G. O. Roberts, A. M. Stuart, D. White. "MCMC methods for
functions: modifying old algorithms to make them faster." Statistical Science
28, 2013 (pCN).
I. Papaioannou, W. Betz, K. Zwirglmaier, D. Straub. "MCMC algorithms for subset
simulation." Probabilistic Engineering Mechanics 41, 2015.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.families.base import FloatArray
from avrisk.rare.problem import SAMPLE_CHUNK, RareEventProblem
from avrisk.rare.splitting_levels import (
    ParticleSet,
    SplittingError,
    SplittingState,
    chain_correlation,
)

#: Acceptance rate the pCN step ``beta`` is adapted towards.
TARGET_ACCEPTANCE = 0.3
#: Gain of the adaptation: ``log beta`` moves by this times the acceptance error.
ADAPT_GAIN = 1.0
#: Smallest pCN step.
MIN_BETA = 1e-3
#: Rounds in a row in which no chain accepts before the run stops.
MAX_ROUNDS_WITHOUT_MOVE = 10
#: Variance inflation of a set's share by its chains' correlation beyond which
#: the next set's chains move ``correlated_moves`` times more.
CORRELATED = 3.0


class MovedSet(NamedTuple):
    """A new particle set and what making it cost.

    Attributes
    ----------
    z : ndarray of shape (N, D)
        The set's particles in standard-normal space, chain after chain.
    values : ndarray of shape (n_chains, max_length)
        ``f`` by chain, as in :class:`~avrisk.rare.splitting_levels.ParticleSet`.
    acceptance : float
        Share of the pCN proposals accepted (NaN for draws of ``P0``).
    n_calls : int
        Calls of ``f`` that made the set.
    beta, n_stages, n_failed, rounds_without_move
        As in :class:`~avrisk.rare.splitting_levels.SplittingState`, after
        the set (``n_failed``: this set's failures only).
    """

    z: FloatArray
    values: FloatArray
    acceptance: float
    n_calls: int
    beta: float
    n_stages: int
    n_failed: int
    rounds_without_move: int


def draw_p0(
    state: SplittingState, problem: RareEventProblem, context: EstimationContext, n: int
) -> MovedSet:
    """Set 0: ``n`` draws of ``P0`` (standard normals mapped by the base)."""
    empty = MovedSet(
        np.empty((0, problem.base.dim)),
        np.empty((0, 1)),
        math.nan,
        0,
        state.beta,
        state.n_stages,
        0,
        state.rounds_without_move,
    )
    return drawn_more(empty, problem, context, n)


def drawn_more(
    first: MovedSet, problem: RareEventProblem, context: EstimationContext, n: int
) -> MovedSet:
    """The first set with ``n`` more draws of ``P0``, a stage of their own."""
    stage = first.n_stages + 1
    z = np.random.default_rng([context.seed, stage]).standard_normal(
        (n, problem.base.dim)
    )
    values, n_failed, n_stages = _evaluate(problem, context, z, stage)
    return first._replace(
        z=np.concatenate([first.z, z]),
        values=np.concatenate([first.values, values[:, None]]),
        n_calls=first.n_calls + n,
        n_stages=first.n_stages + n_stages,
        n_failed=first.n_failed + n_failed,
    )


def moves_after(last: ParticleSet, n_moves: int, correlated_moves: int) -> int:
    """Proposals per kept state for the chains that start from ``last``'s survivors.

    ``n_moves``, times ``correlated_moves`` where the chains that made
    ``last`` were correlated beyond ``CORRELATED`` at its level (*Moves*).
    """
    inflation = chain_correlation(last.values, last.level)
    return n_moves * (correlated_moves if inflation > CORRELATED else 1)


def move_chains(
    state: SplittingState,
    problem: RareEventProblem,
    context: EstimationContext,
    n_moves: int,
    n: int,
) -> MovedSet:
    """The next set, ``n`` states of chains from the last set's survivors (pCN)."""
    last = state.sets[-1]
    flat = last.flat
    seeds = np.flatnonzero(flat <= last.level)
    n_chains = seeds.size
    lengths = np.full(n_chains, n // n_chains)
    lengths[: n % n_chains] += 1  # the longer chains first: who moves is a prefix
    z_chain = np.zeros((n_chains, lengths[0], state.z.shape[1]))
    values = np.full((n_chains, lengths[0]), np.nan)
    z_chain[:, 0], values[:, 0] = state.z[seeds], flat[seeds]
    beta, n_stages, stuck = state.beta, state.n_stages, state.rounds_without_move
    accepted = proposed = n_failed = 0
    for position in range(1, lengths[0]):
        moving = int(np.count_nonzero(lengths > position))
        z, f = z_chain[:moving, position - 1], values[:moving, position - 1]
        for _ in range(n_moves):
            stage = n_stages + 1
            eps = np.random.default_rng([context.seed, stage]).standard_normal(z.shape)
            proposal = math.sqrt(1 - beta * beta) * z + beta * eps
            f_new, failed, used = _evaluate(problem, context, proposal, stage)
            accept = f_new <= last.level
            z = np.where(accept[:, None], proposal, z)
            f = np.where(accept, f_new, f)
            n_accepted = int(np.count_nonzero(accept))
            beta = _adapted(beta, n_accepted, moving, n_chains)
            stuck = 0 if n_accepted else stuck + 1
            if stuck >= MAX_ROUNDS_WITHOUT_MOVE and beta == MIN_BETA:
                raise SplittingError(
                    f"no chain accepted a pCN proposal in {stuck} rounds in a row at "
                    f"level f <= {last.level:g}, with the smallest step beta = "
                    f"{MIN_BETA:g}: the set below the level may have no volume, or f "
                    "may jump there (a stochastic f whose outcome hardly depends on x?)"
                )
            accepted += n_accepted
            proposed += moving
            n_failed += failed
            n_stages += used
        z_chain[:moving, position], values[:moving, position] = z, f
    present = ~np.isnan(values)
    return MovedSet(
        z_chain[present],
        values,
        accepted / proposed if proposed else math.nan,
        proposed,
        beta,
        n_stages,
        n_failed,
        stuck,
    )


def refreshed(
    moved: MovedSet,
    level: float,
    block: np.ndarray,
    problem: RareEventProblem,
    context: EstimationContext,
) -> tuple[MovedSet, float]:
    """``moved`` after one proposal per state of fresh draws of ``block`` (*Moves*).

    Parameters
    ----------
    moved : MovedSet
        States below ``level``; its ``n_stages`` is the last stage used.
    level : float
        The level a proposal must stay at or below.
    block : ndarray of bool, shape (D,)
        The coordinates drawn afresh.
    problem, context
        As for :func:`move_chains`.

    Returns
    -------
    MovedSet
        The states, each replaced by its proposal where accepted, with the
        calls, stages and failures counted (``acceptance`` stays the moves').
    float
        The share of proposals accepted.
    """
    stage = moved.n_stages + 1
    rng = np.random.default_rng([context.seed, stage])
    proposal = moved.z.copy()
    proposal[:, block] = rng.standard_normal((len(proposal), int(block.sum())))
    f_new, failed, used = _evaluate(problem, context, proposal, stage)
    accept = f_new <= level
    values = moved.values.copy()
    present = ~np.isnan(values)
    values[present] = np.where(accept, f_new, values[present])
    return (
        moved._replace(
            z=np.where(accept[:, None], proposal, moved.z),
            values=values,
            n_calls=moved.n_calls + len(proposal),
            n_stages=moved.n_stages + used,
            n_failed=moved.n_failed + failed,
        ),
        float(np.mean(accept)) if len(accept) else math.nan,
    )


def _adapted(beta: float, n_accepted: int, n_proposed: int, n_chains: int) -> float:
    """``beta`` after a round of ``n_proposed`` proposals from ``n_chains`` chains.

    ``log beta`` moves by ``ADAPT_GAIN`` times the acceptance rate's error,
    weighted by the share of the chains that proposed (a round of a few chains
    at a level's end moves it little).
    """
    error = (n_accepted - TARGET_ACCEPTANCE * n_proposed) / n_chains
    return float(np.clip(beta * math.exp(ADAPT_GAIN * error), MIN_BETA, 1.0))


def _evaluate(
    problem: RareEventProblem,
    context: EstimationContext,
    z: FloatArray,
    first_stage: int,
) -> tuple[FloatArray, int, int]:
    """``f`` at ``T^-1(z)``, at most ``SAMPLE_CHUNK`` rows per stage.

    Returns
    -------
    values : ndarray of shape (n,)
        ``+inf`` where the evaluation failed.
    n_failed : int
    n_stages : int
        Stages used, from ``first_stage`` on.
    """
    parts, n_failed = [], 0
    starts = range(0, len(z), SAMPLE_CHUNK)
    for k, start in enumerate(starts):
        x = problem.base.from_standard_normal(z[start : start + SAMPLE_CHUNK])
        values, failed = context.evaluate(problem, x, first_stage + k, 0)
        parts.append(np.where(failed, np.inf, values))
        n_failed += int(np.count_nonzero(failed))
    return np.concatenate(parts), n_failed, len(starts)
