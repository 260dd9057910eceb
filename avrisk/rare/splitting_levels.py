"""Subset simulation's levels: particle sets, each next level, the estimate.

:mod:`avrisk.rare.splitting` states the method: ``p`` is the product of the
shares of particles of each set at or below the next level. This module holds
what a run keeps (:class:`ParticleSet`, :class:`SplittingState`), the choice
of a level from a set's ``f`` (:func:`next_level`, :func:`on_plateau`) and the
estimate of every threshold from the sets (:func:`levels_estimate`). The
chains that make each set are :mod:`avrisk.rare.splitting_moves`.

Ties
----
Many rollouts may share one value of ``f`` (``inf`` for no encounter, ``0`` for
crashes, a capped or coarse ``f``). The level is still the quantile and the
survivors are counted exactly (``f <= level``). When ties leave more than
``p0_max`` of the particles at or below the quantile, the level moves to the
largest value below the tie: the factor is then the share strictly below it,
counted exactly as generalized splitting does, and the chains stay in ``f <=
level``, so the moves keep the conditional law invariant. The level must fall
at every set: one that cannot (the tie at the current level holds the whole
set) ends the levels with a bound (*Plateaus*).

Plateaus
--------
``f`` may be constant on most of ``P0`` (a TTC capped where nothing closes): a
first set of ``N`` draws may then hold few or no particles below the tie.
When it holds fewer than ``min_survivors`` below it (or every draw at it),
the first set takes ``(plateau_draws - 1) N`` more draws of ``P0``. Its factor
is the share of those further draws alone: the first ``N`` decided that they
were drawn, and a count that decides its own sample size is biased (stopping
at the ``m``-th hit overstates ``p`` by about ``m / (m - 1)``); all of the
set's particles below the level seed chains. With some below, the levels go
on (few chains: a wider interval, from their correlation). With none counted,
the answer is a bound, as naive Monte Carlo's with no hit: ``p`` is reported
as 0 with the interval ``[0, u]``, ``u`` the product of the factors so far
times the exact 95% upper bound of a share of 0 of the last set
(``details["bound_only"]``). The same holds for a later set whose particles
all tie at its level. No run stops on a flat ``f``: it is an event the draws
never came near, not a proof that it cannot happen.

Standard error
--------------
Au & Beck's coefficient of variation: level ``l`` contributes ``delta_l^2 =
(1 - p_l) / (N p_l) (1 + gamma_l)`` with ``gamma_l = 2 sum_k (pairs_k / N)
rho_l(k)``, ``rho_l(k)`` the correlation of the indicators ``1{f <= b_{l+1}}``
``k`` states apart in a chain, estimated over the ``pairs_k`` such pairs of
the level's chains (set 0 is independent: ``gamma_0 = 0``), and ``delta^2 =
sum_l delta_l^2``. The levels are taken as uncorrelated (Au & Beck's
approximation; their positive correlation makes it optimistic, grossly so
where the event is reached through a few particles of some set). ``stderr =
p_hat delta``; the interval is normal on ``log p`` with ``Var(log p_hat) =
log(1 + delta^2)``: ``log p_hat`` is a sum over levels, so closer to normal
than the skewed product, and the interval stays above 0. Subset simulation's
own answer takes this interval or the family tree's
(:mod:`avrisk.rare.splitting_genealogy`: that correlation counted, with
Student's t), whichever is wider, and so do ``splitting_is``'s levels, which
answer where its proposal cannot hold what they found (ten regions in ``d =
200``: Au & Beck's said 0.20 of ``log p``'s spread of 0.24, the wider one
0.23; BENCHMARKS.md, "The levels' bias and their precision").

Bias
----
Levels set by the particles themselves (each the ``p0``-quantile of the set
it ends) make the product biased upwards, by ``O(1/N)``: Cérou, Del Moral,
Furon & Guyader (2012) show that with ``n_0`` such levels and independent
draws at each, ``E[p_hat] / p - 1 -> n_0 (1 - p_0) / (N p_0)``, the sum of
those levels' ``delta_l^2``. The correlated chains make each ``delta_l^2``
larger (``1 + gamma_l``) and the bias with it, and with few particles per
failure region it is large: ten regions in ``d = 200`` at ``N = 1,250`` ran
12% high over 150 seeds (BENCHMARKS.md, "The levels' bias"). Every estimate
is therefore divided by ``1 + sum_l delta_l^2`` over the levels above its
threshold (the last share, counted below a fixed threshold, adds none): the
first-order correction, with the chains' correlation in it as in the error.
Use ``N >= 1000`` all the same: the correction is of first order.

References
----------
F. Cérou, P. Del Moral, T. Furon, A. Guyader. "Sequential Monte Carlo for
rare event estimation." Statistics and Computing 22, 2012.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy import stats

from avrisk.rare.families.base import FloatArray
from avrisk.rare.final_stage import CONFIDENCE
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate, GammaEstimate
from avrisk.rare.splitting_genealogy import (
    FamilyTreeError,
    family_tree_error,
    interval_quantile,
)

#: Standard normal quantile of the intervals' confidence (1.96 for 95%).
Z_CONFIDENCE = float(stats.norm.ppf(0.5 + CONFIDENCE / 2))

STDERR_METHOD = (
    "Au & Beck (2001) coefficient of variation: per level (1 - p_l) / (N p_l) "
    "(1 + gamma_l), gamma_l from the indicators' correlation along the chains, "
    "summed over levels taken as uncorrelated"
)
TREE_METHOD = (
    "the family tree's: the spread of the hits over the chains of a set they "
    "descend from, with Au & Beck's for the levels before it, and Student's t "
    "at their effective number less one (the widest interval of either)"
)
INTERVAL_METHOD = (
    "log-normal: normal on log p, Var(log p) = log(1 + cov^2), cov from the "
    "levels' survivor counts and the chains' correlation"
)


def interval_method(dof: float) -> str:
    """How a levels' interval was made: normal (``inf``), or Student's t."""
    if math.isinf(dof):
        return INTERVAL_METHOD
    return (
        f"log-normal with Student's t at {dof:.1f} degrees of freedom: cov from "
        "the spread of the hits over the families they descend from"
    )


class SplittingError(ValueError):
    """The levels cannot reach ``gamma`` (the message says why)."""


class ParticleSet(NamedTuple):
    """The ``N`` particles of one level, by chain.

    Attributes
    ----------
    values : ndarray of shape (n_chains, max_length)
        ``f`` of chain ``j``'s state ``i`` (``+inf`` where its evaluation
        failed, NaN past the chain's end). Set 0 has ``N`` chains of length 1.
    level : float
        The next level chosen from these particles (``gamma`` on the last set).
    counted_from : int, default=0
        First chain whose states the set's factor counts: ``N`` for a first
        set grown on a plateau, whose first ``N`` draws decided that it grows
        (*Plateaus*), else 0.
    """

    values: FloatArray
    level: float
    counted_from: int = 0

    @property
    def flat(self) -> FloatArray:
        """The ``N`` values, chain after chain, shape (N,)."""
        return self.values[~np.isnan(self.values)]

    @property
    def counted(self) -> FloatArray:
        """The chains the factor counts, shape (n_chains - counted_from, max_length)."""
        return self.values[self.counted_from :]


class SplittingState(NamedTuple):
    """What the next level needs.

    Attributes
    ----------
    z : ndarray of shape (N, D)
        The last set's particles in standard-normal space, in the order of
        ``sets[-1].flat`` (shape (0, D) before the first step).
    sets : tuple of ParticleSet
        Every set so far (the estimate of every threshold reads them).
    beta : float
        pCN step for the next moves.
    reached : bool
        Whether the last set's level is ``gamma`` (the steps are over).
    n_stages : int
        Stages (evaluated batches) used so far.
    n_evals : int
        Calls of ``f`` so far.
    n_failed : int
        Evaluations that failed so far.
    rounds_without_move : int
        Rounds in a row in which no chain accepted.
    exhausted : bool, default=False
        Whether ``max_levels`` sets ended above ``gamma`` (the steps are over,
        without a product: its run is regrown, or the answer falls back on
        the first draws,
        :func:`~avrisk.rare.splitting_replicates.first_draws_estimate`).
    """

    z: FloatArray
    sets: tuple[ParticleSet, ...]
    beta: float
    reached: bool
    n_stages: int
    n_evals: int
    n_failed: int
    rounds_without_move: int
    exhausted: bool = False


def levels_estimate(
    state: SplittingState,
    problem: RareEventProblem,
    n_particles: int,
    genealogy: bool = False,
) -> Estimate:
    """Subset simulation's estimate of every threshold from a run's particle sets.

    ``details`` holds the levels, the survivors of each set, their c.o.v.s,
    the first set's draws, whether the answer is a bound only (no particle at
    or below ``gamma``: *Plateaus*) and the failed evaluations. With
    ``genealogy`` the error is the larger of Au & Beck's and the family tree's
    (:mod:`avrisk.rare.splitting_genealogy`), and ``details["ancestors"]`` is
    the fewest effective ancestors of the hits at ``gamma`` in any set (None
    with no hit), ``details["dof"]`` each threshold's interval's degrees of
    freedom (None: normal).
    """
    by_gamma, dofs, trees = {}, [], {}
    for g in problem.thresholds:  # gamma first: its upper end bounds the others'
        bound = by_gamma[problem.gamma].ci[1] if by_gamma else 1.0
        trees[g] = _family_tree(state.sets, g) if genealogy else None
        by_gamma[g], dof = _estimate_at(state.sets, g, trees[g], bound)
        dofs.append(None if math.isinf(dof) else dof)
    details = {
        "levels": [ps.level for ps in state.sets],
        "survivors": _survivors(state.sets),
        "level_cov": [
            math.sqrt(level_cov_squared(ps.counted, ps.level)) for ps in state.sets
        ],
        "n_particles": n_particles,
        "first_set_draws": state.sets[0].flat.size,
        "bound_only": by_gamma[problem.gamma].n_hits == 0,
        "n_failed": state.n_failed,
        "stderr_method": STDERR_METHOD,
    }
    if genealogy:
        ancestors = trees[problem.gamma].ancestors
        details["ancestors"] = ancestors if math.isfinite(ancestors) else None
        details["dof"] = dofs
        details["stderr_method"] = f"{STDERR_METHOD}, or {TREE_METHOD}"
    return Estimate(
        method="subset_simulation",
        gamma=problem.gamma,
        by_gamma=by_gamma,
        n_evals=state.n_evals,
        details=details,
    )


def deepest_mass(state: SplittingState) -> GammaEstimate:
    """``P0(f <= l)`` at the deepest level ``l`` a run's sets reached.

    For a run that ran out of levels above ``gamma``
    (``state.exhausted``): the mass of ``f <= l`` along the mechanism its
    chains followed, which bounds what that mechanism can still hold of the
    event below ``l``.
    """
    return _estimate_at(state.sets, state.sets[-1].level, tree=None)[0]


def next_level(
    values: FloatArray,
    current: float,
    gamma: float,
    p0: float,
    p0_max: float,
) -> float | None:
    """The next level from a particle set's ``f`` (*Ties* in the module docstring).

    Parameters
    ----------
    values : ndarray of shape (N,)
        ``f`` of the set's particles (``+inf`` for failed ones), all at or
        below ``current``.
    current : float
        Level the set is conditioned on (``inf`` for draws of ``P0``).
    gamma : float
        Threshold of the event.
    p0, p0_max : float
        Quantile level; largest share of survivors ties may leave.

    Returns
    -------
    float or None
        ``gamma`` when the ``p0``-quantile is at or below it, else a level
        below ``current``; None when none can fall below it (every particle
        at ``current``: a plateau).

    Examples
    --------
    >>> values = np.array([0.0, 1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    >>> float(next_level(values, np.inf, -1.0, p0=0.2, p0_max=0.5))  # 5 survivors
    1.0
    >>> float(next_level(values, np.inf, -1.0, p0=0.2, p0_max=0.4))  # below the ties
    0.0
    >>> print(next_level(np.full(10, 7.0), 7.0, -1.0, p0=0.2, p0_max=0.5))
    None
    """
    quantile = float(np.quantile(values, p0, method="inverted_cdf"))
    if quantile > gamma and np.count_nonzero(values <= quantile) > p0_max * values.size:
        below = values[values < quantile]
        if below.size:
            quantile = float(below.max())
    if max(quantile, gamma) >= current:
        return None
    return max(quantile, gamma)


def level_cov_squared(values: FloatArray, threshold: float) -> float:
    """Au & Beck's squared c.o.v. of a set's share of ``f <= threshold``.

    Parameters
    ----------
    values : ndarray of shape (n_chains, max_length)
        ``f`` by chain, NaN past each chain's end (:class:`ParticleSet`).
    threshold : float

    Returns
    -------
    float
        ``(1 - p) / (N p) (1 + gamma)`` (:func:`chain_correlation`); 0 when
        ``p`` is 0 or 1.
    """
    n = int(np.count_nonzero(~np.isnan(values)))
    p = np.count_nonzero(values <= threshold) / n
    if p in (0.0, 1.0):
        return 0.0
    return (1 - p) / (n * p) * chain_correlation(values, threshold)


def chain_correlation(values: FloatArray, threshold: float) -> float:
    """How many times the chains' correlation inflates the variance of a set's share.

    Parameters
    ----------
    values : ndarray of shape (n_chains, max_length)
        ``f`` by chain, NaN past each chain's end (:class:`ParticleSet`).
    threshold : float

    Returns
    -------
    float
        ``max(1, 1 + gamma)``, ``gamma = 2 sum_k (pairs_k / N) rho(k)`` over
        the lags ``k`` within chains, ``rho(k)`` the autocorrelation of the
        indicator ``f <= threshold`` (Au & Beck); 1 when ``p`` is 0 or 1.
    """
    present = ~np.isnan(values)
    hits = values <= threshold
    n = int(present.sum())
    p = np.count_nonzero(hits) / n
    if p in (0.0, 1.0):
        return 1.0
    variance = p * (1 - p)
    correlation = 0.0
    for lag in range(1, values.shape[1]):
        pairs = np.count_nonzero(present[:, :-lag] & present[:, lag:])
        both = np.count_nonzero(hits[:, :-lag] & hits[:, lag:])
        correlation += pairs / n * (both / pairs - p * p) / variance
    # chains of pCN states are positively correlated; a negative estimate is
    # noise, and would make the interval narrower than independent draws'
    return max(1.0, 1 + 2 * correlation)


def _survivors(sets: Sequence[ParticleSet]) -> list[int]:
    """Each set's number of particles at or below its level."""
    return [int(np.count_nonzero(ps.flat <= ps.level)) for ps in sets]


def _factors(sets: Sequence[ParticleSet]) -> list[float]:
    """Each set's factor: the share of its counted states at or below its level."""
    return [_share(ps.counted, ps.level) for ps in sets]


def _share(values: FloatArray, threshold: float) -> float:
    """Share of the present (non-NaN) ``values`` at or below ``threshold``."""
    present = values[~np.isnan(values)]
    return np.count_nonzero(present <= threshold) / present.size


def on_plateau(
    values: FloatArray, gamma: float, p0: float, p0_max: float, min_survivors: int
) -> bool:
    """Whether draws of ``P0`` hold too few particles below a tie (*Plateaus*).

    Parameters
    ----------
    values : ndarray of shape (N_0, 1)
        ``f`` of the first set's draws.
    gamma : float
        Threshold of the event.
    p0, p0_max : float
        Quantile level; largest share of survivors ties may leave
        (:func:`next_level`).
    min_survivors : int
        Fewest draws below a tie at their level that are not a plateau.
    """
    flat = values.ravel()
    level = next_level(flat, math.inf, gamma, p0, p0_max)
    if level is None:  # every draw at +inf
        return True
    # without ties the level keeps at least p0 N survivors: fewer means a tie
    survivors = int(np.count_nonzero(flat <= level))
    few = min(min_survivors, p0 * flat.size)
    return level > gamma and (survivors < few or survivors == flat.size)


def _deepest(sets: Sequence[ParticleSet], g: float) -> int:
    """The deepest set conditioned on a level at or above ``g``."""
    return max(i for i in range(len(sets)) if i == 0 or sets[i - 1].level >= g)


def _family_tree(sets: Sequence[ParticleSet], g: float) -> FamilyTreeError:
    """The family tree's error of ``P0(f <= g)`` from the sets."""
    deepest = _deepest(sets, g)
    tree = [(ps.values, ps.level, ps.counted_from) for ps in sets[: deepest + 1]]
    level_cov = [level_cov_squared(ps.counted, ps.level) for ps in sets[:deepest]]
    return family_tree_error(tree, sets[deepest].flat <= g, level_cov)


def lognormal_interval(
    p: float, cov_squared: float, dof: float = math.inf
) -> tuple[float, float]:
    """``p``'s interval, normal on ``log p`` with ``Var(log p) = log(1 + cov^2)``.

    With finite ``dof``, Student's t quantile instead of the normal one (a
    variance estimated from few families: :mod:`avrisk.rare.splitting_genealogy`).
    The upper end is at most 1.
    """
    half = interval_quantile(dof) * math.sqrt(math.log1p(cov_squared))
    return (p * math.exp(-half), min(1.0, p * math.exp(half)))


def _estimate_at(
    sets: Sequence[ParticleSet],
    g: float,
    tree: FamilyTreeError | None,
    bound: float = 1.0,
) -> tuple[GammaEstimate, float]:
    """``P0(f <= g)`` from the deepest set conditioned on a level ``>= g``.

    The product of the factors above it and that set's share at or below
    ``g``, divided by ``1 +`` the factors' ``delta_l^2`` (*Bias*). With its
    interval's degrees of freedom: ``inf`` (normal) unless the family tree's
    interval at ``g`` (``tree``,
    :func:`~avrisk.rare.splitting_genealogy.family_tree_error`) is wider
    than Au & Beck's, whose error and t it then takes.

    With no particle of that set at or below ``g``, ``p`` is 0 and the
    interval reaches up to the upper end of the factors above times the exact
    upper bound of a share of 0 of that set, or ``bound`` if lower (the
    interval of ``gamma``, for ``g`` below it).
    """
    deepest = _deepest(sets, g)
    above = sets[:deepest]
    counted = sets[deepest].counted
    n_last = int(np.count_nonzero(~np.isnan(counted)))
    n_hits = int(np.count_nonzero(counted <= g))
    p_above = math.prod(_factors(above))
    cov_levels = sum(level_cov_squared(ps.counted, ps.level) for ps in above)
    p = p_above * n_hits / n_last / (1.0 + cov_levels)  # *Bias*
    cov_squared = cov_levels + level_cov_squared(counted, g)
    dof = math.inf
    if tree is not None and tree.half_width() > Z_CONFIDENCE * math.sqrt(
        math.log1p(cov_squared)
    ):
        cov_squared, dof = tree.cov_squared, tree.dof
    if n_hits:
        ci = lognormal_interval(p, cov_squared, dof)
    else:  # the upper ends of the factors above and of a share of 0
        half = Z_CONFIDENCE * math.sqrt(math.log1p(cov_levels))
        upper_above = p_above * math.exp(half)
        upper = -math.expm1(math.log((1 - CONFIDENCE) / 2) / n_last)
        ci = (0.0, min(bound, upper_above * upper))
    estimate = GammaEstimate(
        gamma=g,
        p=p,
        stderr=p * math.sqrt(cov_squared),
        ci=ci,
        n_hits=n_hits,
        ess=float(n_hits),
        n_samples=n_last,
        confidence=CONFIDENCE,
        interval=interval_method(dof),
    )
    return estimate, dof
