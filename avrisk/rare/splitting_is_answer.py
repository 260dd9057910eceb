"""The importance-sampling stage of ``splitting_is``, its answer and doubts.

:class:`~avrisk.rare.splitting_importance.SplittingImportanceSampling` ends
with two estimates from the same budget: the importance sample from the
proposal fitted to the particles, and the levels' own product (the
replicates' mean). The importance-sampling estimate answers: the proposal is
fixed before its samples are drawn, so it is unbiased whatever the particles,
and its standard error is the weighted mean's (the usual CLT interval,
trusted while the hits' weights have Pareto ``k <= 0.7``). Unless the
particles say beforehand that the levels' product will be more precise
(:func:`levels_more_precise`): the particles' weights under fits to the other
folds of the chains predict the importance sample's error, both the share of
``p`` it will miss (where its proposal is no denser than ``P0``) and its
variance on the rest, and a proposal that cannot hold what they found (many
regions with few particles each in many dimensions; a set that narrows
``P0``'s spread rather than shifting it) predicts a large one. The levels
never answer once a replicate ran out of levels, regrown or not: their error
does not see the near miss its chains followed. ``details["answer"]`` says
which (``"importance_sampling"`` or ``"splitting"``); both estimates are kept
in ``details``
(``importance_sampling``, ``splitting``, each replicate's in
``details["replicates"]``) as a cross-check: the two are not independent (the
run's particles made the proposal) but have different errors.

:func:`importance_stage` draws the importance sample and makes that choice.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.final_stage import (
    MIN_RELIABLE_ESS,
    Advice,
    weighted_stage_estimates,
)
from avrisk.rare.particle_fit import ParticleFit
from avrisk.rare.particle_predictions import HeldOutWeights
from avrisk.rare.problem import FINAL_STAGE, RareEventProblem
from avrisk.rare.results import Estimate, GammaEstimate
from avrisk.rare.splitting_replicates import (
    disagreement_doubts,
    estimates_disagree,
    exhausted_doubts,
    few_survivors,
    per_replicate,
)
from avrisk.rare.stages import StageResult

__all__ = [
    "ADVICE",
    "SAMPLED_KEYS",
    "answer_doubts",
    "importance_stage",
    "levels_more_precise",
]

#: Remedies of an unreliable importance-sampling stage, in its settings' names.
ADVICE = Advice(
    no_hit="raise n_final, or n_particles (the proposal is fitted to them)",
    degenerate="the proposal fitted to the particles is degenerate: raise "
    "n_particles or defensive, and compare subset simulation's own estimate of "
    "the run (details['splitting'])",
    heavy_tail="raise n_particles and n_final, or compare subset simulation's own "
    "estimate of the run (details['splitting']) and runs with other seeds",
)

#: What ``details["importance_sampling"]`` keeps of the sample's estimate at
#: each threshold (the answer's may be the levels').
SAMPLED_KEYS = ("p", "stderr", "ci", "n_hits", "ess", "pareto_k")


def importance_stage(
    fitted: ParticleFit,
    problem: RareEventProblem,
    context: EstimationContext,
    n_final: int,
    n_evals: int,
    levels: Estimate | None,
) -> tuple[StageResult, dict[float, GammaEstimate], bool]:
    """The final stage, its estimates, and whether the levels answer instead.

    ``n_final`` draws of the fitted proposal after ``n_evals`` calls of
    ``f``, estimated per threshold. The levels' estimate ``levels`` answers
    where the particles predicted it more precise
    (:func:`~avrisk.rare.splitting_is_answer.levels_more_precise`; never
    when it is None); otherwise the sample's warnings are the answer's and
    are raised again.
    """
    stage = context.stage(
        problem, fitted.proposal, n_final, FINAL_STAGE, final_after=n_evals
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sampled = weighted_stage_estimates(stage, problem.thresholds, ADVICE)
    from_levels = levels is not None and levels_more_precise(
        fitted.held_out, levels.by_gamma[problem.gamma], n_final
    )
    if not from_levels:  # the sample's doubts are the answer's
        for caught_warning in caught:
            warnings.warn_explicit(
                caught_warning.message,
                caught_warning.category,
                caught_warning.filename,
                caught_warning.lineno,
            )
    return stage, sampled, from_levels


def levels_more_precise(
    held_out: HeldOutWeights, levels: GammaEstimate, n_final: int
) -> bool:
    """Whether the levels' estimate is expected to be nearer ``p`` than the IS stage's.

    Decided before the importance sample is drawn, from the particles'
    held-out weights (:class:`~avrisk.rare.particle_fit.HeldOutWeights`):
    the importance sample misses the share ``s`` of ``p`` where its proposal
    is no denser than ``P0``, and on the rest its ``n_final`` draws have
    relative variance ``(E[w 1{w < 1} | F] / p - (1 - s)^2) / n_final``, so
    its expected squared relative error is ``s^2`` plus that; the levels'
    is ``(stderr / p)^2``, with ``p`` the levels' estimate. Where the
    proposal cannot hold what the particles found (many regions with few
    particles each in many dimensions; a set that narrows ``P0``'s spread
    rather than shifting it) the levels' product is the better answer; where
    it can, the importance sample's. The decision uses the particles only,
    never the importance sample, so it selects no draw of it. It does use the
    levels' ``p``: a low one favours the levels, but only near the break-even
    point, where the two are about equally precise.
    """
    p, stderr = levels.p, levels.stderr
    s, covered = held_out
    if not (math.isfinite(s) and p > 0 and math.isfinite(stderr)):
        return False
    sampled = max(covered / p - (1.0 - s) ** 2, 0.0) / n_final
    return s**2 + sampled > (stderr / p) ** 2


def answer_doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
    """Replicates that ran out of levels, or an answer the other estimate belies.

    The doubts of ``estimate`` (a ``splitting_is`` run as a dict) at
    ``gamma``. Few particles at a level do not bias the importance-sampling
    stage (its weights' diagnostics speak for it), nor do replicates that
    ended in different places: the proposal holds what either found
    (*Replicates* in :mod:`avrisk.rare.splitting_importance`). But an
    importance-sampling answer below the levels' estimate, beyond both
    errors (:func:`_sample_below_levels`), says the proposal misses where the
    particles were (a shift
    fitted on too few coordinates, a region dropped), which its weights alone
    may not show. One above them does not: a proposal cannot add mass the
    event lacks (the sample is unbiased; a single huge weight is its Pareto
    k's to show), so the levels lost part of the event, as they do when their
    chains follow a near miss. When the levels answer (the module docstring),
    their own doubts count (subset simulation's), and so does an importance
    sample that belies them (:func:`_levels_answer_doubts`). Replicates that
    ran out of levels are doubted as
    :func:`~avrisk.rare.splitting_replicates.exhausted_doubts` says: under an
    importance-sampling answer, only where the mass their mechanism reached
    may exceed the answer's standard error.
    """
    details = estimate.get("details") or {}
    main = next((g for g in estimate.get("by_gamma", ()) if g["gamma"] == gamma), None)
    own = details.get("replicates") or []
    if gamma != estimate.get("gamma") or main is None:
        return ()
    if not own:  # no replicate reached gamma (or none was recorded)
        return _none_reached(details)
    sampled = details.get("answer") != "splitting"
    reasons = list(exhausted_doubts(details, main if sampled else None))
    if not sampled:
        reasons[:0] = _levels_answer_doubts(details, main, gamma)
    elif _sample_below_levels(details, main, gamma):
        levels = ", ".join(f"{r['p']:.2g}" for r in own)
        pooled = _pooled_levels(details, gamma)
        if pooled and len(own) > 1:
            levels = f"{pooled['p']:.2g} (replicates {levels})"
        reasons.append(
            f"importance sampling found p = {main['p']:.2g} but the levels of "
            f"the same run {levels}, further apart than their errors allow: "
            "the proposal may miss part of the failure set (compare runs with "
            "other seeds, or raise n_particles)"
        )
    return tuple(reasons)


def _sample_below_levels(
    details: dict[str, Any], main: dict[str, Any], gamma: float
) -> bool:
    """Whether an importance-sampling answer lies below the levels beyond both errors.

    The reference is the replicates' pooled product (the run's own levels'
    estimate, ``details["splitting"]``), the most precise the levels give,
    where the replicates agree with each other and each found more than the
    answer: a replicate whose own estimate is at or below it bears it out.
    Where the replicates disagree (``replicates_disagree``), their pool is
    no fair reference: the answer is doubted only when it lies below every
    replicate's estimate beyond both errors, as one that a replicate bears
    out may be right where the other replicate's levels went astray.
    """
    own = details.get("replicates") or []

    def below(levels: dict[str, Any]) -> bool:
        return main["p"] < levels["p"] and estimates_disagree(main, levels)

    below_each = all(below(r) for r in own)
    pooled = _pooled_levels(details, gamma)
    if details.get("replicates_disagree") or not pooled:
        return below_each
    borne_out = any(r["p"] <= main["p"] for r in own)
    return below_each or (below(pooled) and not borne_out)


def _pooled_levels(details: dict[str, Any], gamma: float) -> dict[str, Any] | None:
    """The pooled levels' estimate at ``gamma`` (``{"p", "ci"}``), if any."""
    return (details.get("splitting") or {}).get(str(gamma))


def _none_reached(details: dict[str, Any]) -> tuple[str, ...]:
    """The doubt of a run no replicate of which reached ``gamma``."""
    if not details.get("replicates_exhausted"):
        return ()
    deepest = min(min(levels) for levels in per_replicate(details["levels"]))
    return (
        "no replicate of the search reached gamma within max_levels levels, "
        "regrown as far as regrow and max_calls allow (they followed a "
        "mechanism that does not end in the event): p is importance sampling's "
        f"from particles at f <= {deepest:.3g}, a bound where it has no hit "
        "(raise n_particles, or max_levels)",
    )


def _levels_answer_doubts(
    details: dict[str, Any], main: dict[str, Any], gamma: float
) -> list[str]:
    """The levels' own doubts, and an importance sample that belies them.

    The levels' own are subset simulation's
    (:meth:`~avrisk.rare.splitting.SubsetSimulation.doubts`): a level held by
    a handful of particles, replicates whose products disagree. An importance
    sample from their particles belies them when it lies further from them
    than both errors allow: above them (it cannot add mass the event lacks,
    so the levels lost part of it), or below them with at least
    ``MIN_RELIABLE_ESS`` effective hits. Below them with fewer, its estimate
    is a handful of weights, and such a sample falls low as a rule (its
    largest weights are not drawn), which is what the particles predicted
    when the levels were chosen. (A heavy tail of the weights, Pareto ``k >
    0.7``, does not silence it: in many dimensions the sample's heavy-tailed
    estimate still falls far below levels that are twice too high.)
    """
    reasons = list(few_survivors(details.get("survivors") or []))
    reasons += disagreement_doubts(details)
    sampled = (details.get("importance_sampling") or {}).get(str(gamma))
    if not (sampled and "stderr" in sampled and estimates_disagree(sampled, main)):
        return reasons
    if sampled["p"] > main["p"] or (sampled.get("ess") or 0.0) >= MIN_RELIABLE_ESS:
        reasons.append(
            f"the levels found p = {main['p']:.2g} but importance sampling "
            f"from their particles {sampled['p']:.2g}, further apart than "
            "their errors allow: the levels may have lost part of the "
            "failure set (compare runs with other seeds, or raise "
            "n_particles)"
        )
    return reasons
