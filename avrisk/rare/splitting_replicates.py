"""Independent replicates of subset simulation's levels, and what they say together.

:class:`~avrisk.rare.splitting_importance.SplittingImportanceSampling` runs
its levels ``replicates`` times, independently (*Replicates* in its module).
This module holds what the replicates share: their state
(:class:`ReplicatesState`), the rule that regrows one that ran out of levels
(:func:`regrowth_fits`), their levels' combined estimate
(:func:`combined_levels`), the chain numbers of their pooled particles
(:func:`pooled_chains`), and the checks of disagreement between replicates
(:func:`replicates_disagree`) and between the levels and an importance sample
(:func:`estimates_disagree`).

Regrowth. A replicate whose ``max_levels`` sets end above ``gamma`` followed a
mechanism of low ``f`` that does not end in the event: the chains of a set
move within the region they are in, and a rarer region that leads to
``gamma`` survives a level only through its share of the ``p0 N`` survivors.
Twice the particles keep twice as many of them, so the replicate runs again,
fresh (new random numbers, its own stages), with twice the particles, while
the settings' count and cap allow (:func:`regrowth_fits`). The runs it
replaces are kept in the record (their levels are shown) but not in any
estimate: their product is that of the wrong mechanism.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from avrisk.rare.families.base import FloatArray
from avrisk.rare.final_stage import MIN_RELIABLE_ESS, binomial_estimates
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate
from avrisk.rare.splitting_genealogy import interval_quantile, satterthwaite_dof
from avrisk.rare.splitting_levels import (
    Z_CONFIDENCE,
    SplittingState,
    deepest_mass,
    interval_method,
    lognormal_interval,
)

__all__ = [
    "DISAGREEMENT_Z",
    "ReplicatesState",
    "combined_levels",
    "disagreement_doubts",
    "estimates_disagree",
    "exhausted_doubts",
    "few_survivors",
    "first_draws_estimate",
    "per_replicate",
    "pooled_chains",
    "regrown_doubts",
    "regrowth_fits",
    "replicates_disagree",
    "replicates_record",
]

#: Standard errors of the difference of two replicates' ``log p`` beyond which
#: they disagree (*Replicates*): two-sided 0.3% for normal errors, as subset
#: simulation's own errors are somewhat optimistic.
DISAGREEMENT_Z = 3.0


def replicates_disagree(own: Sequence[Estimate]) -> bool:
    """Whether two replicates' estimates of ``p`` disagree beyond their errors.

    Two with hits disagree when their ``log p`` differ by more than
    ``DISAGREEMENT_Z`` standard errors (:func:`_log_variance`); one with hits
    and one without, when the first's interval lies above the second's
    bound. Independent searches that end in different places are the sign of
    a failure region one of them did not find, and so perhaps one that none
    found.
    """
    for i, a in enumerate(own):
        for b in own[i + 1 :]:
            if a.n_hits and b.n_hits:
                var = sum(_log_variance(e) for e in (a, b))
                if abs(np.log(a.p / b.p)) > DISAGREEMENT_Z * np.sqrt(var):
                    return True
            elif a.n_hits or b.n_hits:
                hit, bound = (a, b) if a.n_hits else (b, a)
                if hit.ci[0] > bound.ci[1]:
                    return True
    return False


def _log_variance(own: Estimate) -> float:
    """A replicate's ``Var(log p)`` at ``gamma``, as wide as its interval says.

    Where the interval took Student's t at ``dof`` degrees of freedom (hits
    of few families: :mod:`avrisk.rare.splitting_genealogy`), the variance
    is scaled by ``(t_dof / z)^2``, so that its normal multiple spans what the
    interval does: a spread read off one or two families is no evidence that
    two replicates differ.
    """
    var = float(np.log1p((own.stderr / own.p) ** 2))
    dof = _dof(own.details, list(own.by_gamma).index(own.gamma))
    if math.isinf(dof):
        return var
    return var * (interval_quantile(dof) / Z_CONFIDENCE) ** 2


def estimates_disagree(sampled: dict[str, Any], levels: dict[str, Any]) -> bool:
    """Whether the importance-sampling and the levels' estimates of ``p`` disagree.

    Both as ``{"p", "ci"}`` (the sampled one with ``stderr``): their ``log
    p`` differ by more than ``DISAGREEMENT_Z`` standard errors, the sampled
    one's ``log(1 + (stderr / p)^2)``, the levels' from their log-normal
    interval's half-width. An estimate of 0 disagrees with one whose interval
    lies above its bound.
    """
    p, q = sampled["p"], levels["p"]
    if p <= 0 or q <= 0:
        return (p > 0 and sampled["ci"][0] > levels["ci"][1]) or (
            q > 0 and levels["ci"][0] > sampled["ci"][1]
        )
    var = np.log1p((sampled["stderr"] / p) ** 2)
    var += (np.log(levels["ci"][1] / q) / Z_CONFIDENCE) ** 2
    return bool(abs(np.log(p / q)) > DISAGREEMENT_Z * np.sqrt(var))


class ReplicatesState(NamedTuple):
    """Replicates of the levels: the finished ones and the one under way.

    Attributes
    ----------
    finished : tuple of SplittingState
        Replicates whose levels are over (reached ``gamma`` or ran out of
        levels), in order.
    current : SplittingState
        The replicate under way (the last one once the levels are done).
    sizes : tuple of int
        Particles per level of each replicate, ``finished``'s then
        ``current``'s.
    filled : int, default=0
        Replicates (of the ``replicates`` the settings ask for) that are over
        and will not be regrown: those in ``finished`` that reached ``gamma``,
        and those that ran out with no regrowth left.
    """

    finished: tuple[SplittingState, ...]
    current: SplittingState
    sizes: tuple[int, ...]
    filled: int = 0

    @property
    def all(self) -> tuple[SplittingState, ...]:
        """Every replicate, ``finished`` then ``current``."""
        return (*self.finished, self.current)

    def reached(self) -> list[tuple[SplittingState, int]]:
        """The replicates that reached ``gamma``, each with its particles per level."""
        return [
            (r, n) for r, n in zip(self.all, self.sizes, strict=True) if not r.exhausted
        ]


def regrowth_fits(
    state: ReplicatesState,
    replicates: int,
    levels_bound: Callable[[int], int],
    tail_bound: Callable[[int], int],
    cap: int,
) -> bool:
    """Whether the replicate that just ran out of levels may run again, twice as large.

    Only if the calls so far plus the most the rest can take stay within
    ``cap``: the regrown replicate's levels (``levels_bound(2 n)``), those of
    the replicates still to start at the first size, and the moves at
    ``gamma`` and final stage on every replicate that may reach it
    (``tail_bound`` of their particles in all).

    Parameters
    ----------
    state : ReplicatesState
        Its ``current`` replicate is over, out of levels.
    replicates : int
        Replicates the run fills.
    levels_bound, tail_bound : callable of int -> int
        The most calls of one replicate's levels with that many particles per
        level; of the moves at ``gamma`` and the final stage on that many
        particles.
    cap : int
        The most calls of ``f`` the run may make.
    """
    grown, first = 2 * state.sizes[-1], state.sizes[0]
    fresh = replicates - state.filled - 1  # replicates after the regrown one
    reached = sum(n for _, n in state.reached())
    rest = levels_bound(grown) + fresh * levels_bound(first)
    rest += tail_bound(reached + grown + fresh * first)
    return state.current.n_evals + rest <= cap


def pooled_chains(values: Sequence[FloatArray]) -> np.ndarray:
    """Chain numbers of the pooled particles of several replicates' moves.

    Parameters
    ----------
    values : sequence of ndarray of shape (n_chains_r, length_r)
        Each replicate's moved states by chain (NaN past a chain's end).

    Returns
    -------
    ndarray of int, shape (n,)
        One number per present state, in the order of the replicates' ``z``:
        the first half of every replicate's chains (in their ancestors' order)
        before all second halves, so the fit's two halves
        (:func:`particle_proposal`) each hold half of every replicate.
    """
    keys = []
    for r, v in enumerate(values):
        c = np.nonzero(~np.isnan(v))[0]
        keys.append(np.stack([c >= (v.shape[0] + 1) // 2, np.full_like(c, r), c], 1))
    key = np.concatenate(keys)
    _, number = np.unique(key, axis=0, return_inverse=True)
    return number.ravel()


def combined_levels(
    own: Sequence[Estimate], problem: RareEventProblem, n_particles: int
) -> Estimate:
    """Subset simulation's estimate of the run: the replicates' mean.

    Each replicate's product estimate has its own error; their mean has
    variance ``sum(stderr_r^2) / R^2`` and a log-normal interval as one
    replicate's, with Welch and Satterthwaite's degrees of freedom where a
    replicate's interval took Student's t
    (:func:`~avrisk.rare.splitting_genealogy.satterthwaite_dof`). Zero hits
    in every replicate: the largest of their bounds (each is a 95% bound of
    ``p`` on its own). ``details`` hold the levels, survivors, level
    c.o.v.s, first set draws and, where the levels' error read their family
    tree, the hits' fewest ancestors and the intervals' degrees of freedom
    per replicate (a list each; one replicate's estimate is its own, with
    one list each: :func:`per_replicate` reads both).
    """
    first = own[0]
    if len(own) == 1:
        return first
    by_gamma = {}
    for i, g in enumerate(first.by_gamma):
        parts = [e.by_gamma[g] for e in own]
        p = float(np.mean([e.p for e in parts]))
        stderr = float(np.sqrt(sum(e.stderr**2 for e in parts))) / len(parts)
        if p > 0:
            dof = satterthwaite_dof(
                [e.stderr**2 for e in parts], [_dof(e.details, i) for e in own]
            )
            ci = lognormal_interval(p, (stderr / p) ** 2, dof)
            interval = interval_method(dof)
        else:
            ci, interval = (0.0, max(e.ci[1] for e in parts)), parts[0].interval
        by_gamma[g] = dataclasses.replace(
            parts[0],
            p=p,
            stderr=stderr,
            ci=ci,
            interval=interval,
            n_hits=sum(e.n_hits for e in parts),
            ess=float(sum(e.ess for e in parts)),
            n_samples=sum(e.n_samples for e in parts),
        )
    keys = ("levels", "survivors", "level_cov", "first_set_draws", "ancestors", "dof")
    present = [key for key in keys if key in first.details]
    details = {key: [e.details[key] for e in own] for key in present}
    details |= {
        "n_particles": n_particles,
        "bound_only": by_gamma[problem.gamma].n_hits == 0,
        "n_failed": sum(e.details["n_failed"] for e in own),
        "stderr_method": first.details["stderr_method"],
    }
    return dataclasses.replace(
        first, by_gamma=by_gamma, n_evals=own[-1].n_evals, details=details
    )


def _dof(details: dict[str, Any], i: int) -> float:
    """Degrees of freedom of a replicate's ``i``-th threshold (``inf``: normal)."""
    dof = (details.get("dof") or [None] * (i + 1))[i]
    return math.inf if dof is None else dof


def replicates_record(
    state: ReplicatesState, own: Sequence[Estimate], replicates: int
) -> dict[str, Any]:
    """What ``details`` keep of the replicates, beside their levels.

    ``replicates``: each that reached ``gamma``, its estimate there;
    ``replicates_disagree`` (:func:`replicates_disagree`);
    ``replicates_exhausted``: those still above ``gamma`` after every
    regrowth the settings allowed (of the ``replicates`` the run fills);
    ``replicates_regrown``: the runs that ran out of levels and were run
    again, larger; ``replicate_particles``: the particles per level of each
    that reached ``gamma``; ``exhausted_mass``: for every run that ran out of
    levels (regrown or not), ``P0(f <= l)`` at its deepest level ``l`` as its
    own sets estimate it (:func:`~avrisk.rare.splitting_levels.deepest_mass`:
    ``level``, ``p`` and the upper end ``upper`` of its interval).
    """
    reached = state.reached()
    exhausted = replicates - len(reached)
    masses = [deepest_mass(r) for r in state.all if r.exhausted]
    return {
        "replicates": [{"p": e.p, "ci": list(e.ci), "n_hits": e.n_hits} for e in own],
        "replicates_disagree": replicates_disagree(own),
        "replicates_exhausted": exhausted,
        "replicates_regrown": sum(r.exhausted for r in state.all) - exhausted,
        "replicate_particles": [n for _, n in reached],
        "exhausted_mass": [
            {"level": m.gamma, "p": float(m.p), "upper": float(m.ci[1])} for m in masses
        ],
    }


def disagreement_doubts(details: dict[str, Any]) -> tuple[str, ...]:
    """The doubt of replicates whose estimates disagree (:func:`replicates_disagree`).

    ``details``: a run's, with ``replicates_disagree`` and each replicate's
    estimate at ``gamma`` in ``replicates``. The levels' product is their
    mean: of products that each miss part of the event.
    """
    if not details.get("replicates_disagree"):
        return ()
    found = ", ".join(f"{r['p']:.2g}" for r in details["replicates"])
    return (
        f"the replicates of the search found p = {found}, further apart than "
        "their errors allow: they followed different parts of the failure set, "
        "and a part none of them found is as likely (compare runs with other "
        "seeds, or raise n_particles)",
    )


def exhausted_doubts(
    details: dict[str, Any], sampled: dict[str, Any] | None = None
) -> tuple[str, ...]:
    """The doubt of replicates that ran out of levels with no regrowth left.

    A levels' answer then rests on the replicates that reached ``gamma``,
    each of which may have squeezed through the same bottleneck: the doubt
    stands. An importance-sampling answer (``sampled``: its estimate at
    ``gamma``, with ``p``, ``stderr`` and ``n_hits``) has its own weights'
    diagnostics for the mechanism it sampled; what a run out of levels adds
    is a mechanism it did not sample, and that mechanism's mass at the
    deepest level its chains reached bounds the event's mass it may still
    hold. When every such run's bound (the upper end of its interval,
    ``details["exhausted_mass"]``) is at most the answer's standard error,
    nothing the mechanism may hold moves ``p`` beyond its own error: no doubt.
    """
    exhausted = details.get("replicates_exhausted") or 0
    if not exhausted:
        return ()
    masses = details.get("exhausted_mass")
    if sampled and sampled.get("n_hits") and masses is not None:
        if max(m["upper"] for m in masses) <= sampled["stderr"]:
            return ()
    of = len(details.get("replicates") or []) + exhausted
    rests = (
        "the answer rests on the others (compare runs with other seeds, or raise "
        "n_particles)"
        if exhausted < of
        else "the answer is naive sampling's of their first draws of P0, a bound "
        "where none hit (raise max_levels or n_particles, or use splitting_is)"
    )
    return (
        f"{exhausted} of the {of} replicates of the search did not reach gamma "
        "within max_levels levels, regrown as far as regrow and max_calls allow "
        f"(they followed a mechanism that does not end in the event): {rests}",
    )


def regrown_doubts(details: dict[str, Any]) -> tuple[str, ...]:
    """The doubt of a levels' answer some of whose replicates were regrown.

    A replicate runs again when its levels followed a near miss; the one that
    reaches ``gamma`` is the luckier of several tries, and its product,
    chosen for having kept the rarer mechanism, leans high.
    """
    regrown = details.get("replicates_regrown") or 0
    if not regrown:
        return ()
    return (
        f"{regrown} runs of the levels ran out before larger ones reached gamma "
        "(a near miss the chains followed): the product of those that reached "
        "it leans high (raise n_particles, or use splitting_is)",
    )


def per_replicate(values: Sequence[Any]) -> list[Sequence[Any]]:
    """A ``details`` list of the levels (``levels``, ``survivors`` ...) by replicate.

    Several replicates record one list each; one replicate, and subset
    simulation's summaries of a single run, one flat list.
    """
    if values and isinstance(values[0], list):
        return list(values)
    return [values]


def few_survivors(survivors: Sequence[Any]) -> tuple[str, ...]:
    """The doubt of a level held by fewer than ``MIN_RELIABLE_ESS`` particles.

    ``survivors``: each set's survivors, by replicate
    (:func:`per_replicate`).
    """
    by_replicate = per_replicate(survivors)
    few = [int(k) for one in by_replicate for k in one[:-1] if k < MIN_RELIABLE_ESS]
    if not few:
        return ()
    return (
        f"a level of the search held only {min(few)} particles below it (f "
        "ties on a plateau?): its interval is likely too narrow",
    )


def first_draws_estimate(
    state: ReplicatesState, problem: RareEventProblem, n_particles: int
) -> Estimate:
    """Naive sampling's estimate of every threshold from the runs' first draws.

    The answer where no run of the levels reached ``gamma``. Every run's first
    set (regrown ones' too) is independent draws of ``P0`` (those counted:
    *Plateaus* in :mod:`avrisk.rare.splitting_levels`); their share at or
    below each threshold, with its exact (Clopper-Pearson) interval, is an
    honest answer: most often 0 with the exact upper bound, as naive Monte
    Carlo's with no hit. The deeper sets' product is not: their chains
    followed a mechanism that does not end in the event, and their estimate
    of ``P0(f <= l)`` at their deepest level can lie far below ``p``.
    """
    draws = np.concatenate([r.sets[0].counted.ravel() for r in state.all])
    draws = draws[~np.isnan(draws)]
    by_gamma = binomial_estimates(draws, problem.thresholds)
    details = {
        "levels": [[ps.level for ps in r.sets] for r in state.all],
        "n_particles": n_particles,
        "first_set_draws": draws.size,
        "bound_only": by_gamma[problem.gamma].n_hits == 0,
        "n_failed": sum(r.n_failed for r in state.all),
        "stderr_method": "binomial, of the first sets' draws of P0",
    }
    return Estimate(
        method="subset_simulation",
        gamma=problem.gamma,
        by_gamma=by_gamma,
        n_evals=state.current.n_evals,
        details=details,
    )
