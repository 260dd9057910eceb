"""Importance sampling from subset simulation's particles.

Subset simulation (:mod:`avrisk.rare.splitting`) ends with ``N`` particles
of ``P0`` conditioned on the level above ``gamma``; those with ``f <= gamma``
are (correlated) draws of the optimal importance density ``P0(. | f <=
gamma)``, found without importance weights: pCN moves leave each conditional
law invariant whatever the dimension. This estimator fits a proposal to them
and estimates ``p`` by importance sampling from it:

1. run subset simulation to ``gamma`` (its levels, moves and ties as there);
2. move chains from the last set's particles with ``f <= gamma`` once more,
   at the level ``gamma`` itself: ``N`` particles of ``P0(. | f <= gamma)``
   (``N`` states, the hits among them: fewer than ``N`` new calls of ``f``;
   the last set alone may hold as few as ``p0 N`` hits), taken in the base's
   standard-normal space, ``z = T(x)``; then, ``refresh_rounds`` times (twice
   by default), draw afresh the coordinates the particles do not inform (one
   proposal per particle, kept if still below the level: *Moves* in
   :mod:`avrisk.rare.splitting_moves`). After a few levels the particles
   can descend from a handful of the first set's draws, each keeping some of
   its ancestor's coordinates where ``f`` does not pull them; fitted, such an
   accident is a shift the event does not have, and the weights it makes
   have a heavy tail (on ``highway_rare`` it multiplied the weights' second
   moment several times; BENCHMARKS.md);
3. keep the coordinates the particles say something about: those where the
   particles' mean differs from 0, or their mean square from 1, by more than
   ``t`` standard errors (from the means of ``N_BLOCKS`` blocks of chains, so
   the chains' correlation is in them). A coordinate on which the event does
   not depend is ``N(0, 1)`` under ``P0(. | f <= gamma)`` too; a shift fitted
   there is noise of variance ``1 / n_eff`` each, ``d / n_eff`` in all, and
   costs a factor of about ``exp(d / n_eff)`` in the weights' second moment:
   fatal when ``d`` is the learned drivers' 404 coordinates or more. A high
   ``t`` drops that noise but also weak real shifts (a failure set that
   depends a little on each of many coordinates); a low one keeps both. Then
   fit mean shifts of ``N(0, I)`` on the kept coordinates, unweighted (the
   particles already follow the target), as mixture cross-entropy fits its
   elites (:mod:`avrisk.rare.mixture_em`): k-means++ seeding, EM, merging of
   components less than one standard deviation apart. Each fitted shift ``m``
   (of ``pi N`` particles) is then shrunk towards 0, James-Stein fashion, to
   ``c m`` with ``c = max(0, 1 - s^2 / (pi |m|^2))``, ``s^2`` the sum of the
   kept coordinates' squared standard errors: ``|m|^2`` overstates the true
   shift's by about that noise, and ``c`` is the scale that minimises the
   expected squared distance to the true shift. ``t = 0`` keeps every
   coordinate and relies on the shrinkage alone: the fit for a failure set
   that depends a little on each of many coordinates (a linear limit state in
   ``D = 1000``), where no single coordinate stands out. The threshold ``t``
   (from ``THRESHOLDS``, with one component), then the number of components
   (from 1 to ``n_components``), is the one whose fits to the particles of one
   half of the chains give the other half's particles the highest mean
   log-likelihood, summed over both ways round (ties to the sparser fit); the
   proposal is then fitted to all particles with those choices, unless one
   more candidate scores higher by more than two standard errors of the
   paired difference (from blocks of chains; a close call goes to the
   per-coordinate fit). It has one component and shifts along a single
   direction, ``f``'s average slope, fitted by least squares to the last
   level's particles and their values (:func:`slope_direction`; exact for a
   linear limit state), by the particles' mean along it. Its noise is ``1 /
   n_eff`` against ``D / n_eff`` for a shift of every coordinate, which is what
   a failure set that depends a little on each of many coordinates needs.
   With ``fit_variances``, the components may also fit each kept
   coordinate's variance around their shift (its noise shrunk away as a
   shift's is; the threshold chosen again for them, since a coordinate whose
   variance alone is off says nothing to a shift), where the held-out halves
   prefer that by two standard errors: an event that holds many coordinates
   small (a sum of squares, a corner of several Betas) has a conditional law
   narrower than ``P0`` in each, and unit variances pay for it in every one.
   The variances stay in ``[0.6, 4]``: below 1/2 a component's weights
   ``p0 / q`` would have infinite variance along that coordinate without the
   defensive share, and near it the conditional law's own tail (that of
   ``P0``, cut by the event) outruns the fit.
   Chains are numbered in the order of their ancestors at every level, so the two halves
   descend from different draws of ``P0`` where the particles descend from
   many (where they descend from a few, both halves share them, which is
   what the refresh of step 2 is for). The
   held-out likelihood of a mean shift falls with its squared distance from
   the other half's mean, so it scores noise admitted and signal dropped
   alike. In high dimension k-means splits one failure region into clusters
   whose means differ by noise of order ``d / n_k`` (``d`` coordinates,
   ``n_k`` particles; more, as a chain's states are correlated), and such a
   split fits the held-out half worse; regions that lie apart fit it better
   split;
4. draw ``n_final`` fresh samples of ``q = lam P0 + (1 - lam) sum_k pi_k
   T^-1(N(mu_k, diag(v_k)))`` (``v_k = 1`` without fitted variances) and
   estimate ``mean(w 1{f <= g})``, ``w = p0 / q <= 1 / lam``, per
   threshold, with ESS and Pareto ``k`` as for every importance sampler.

Why. A cross-entropy search estimates the optimal mean from importance-weighted
elites of its own proposals. In ``D`` dimensions the mean of ``n`` effective
elites misses by about ``D / n`` in squared norm, and that error multiplies
the weights' second moment by about ``exp(D / n)``; the weights of the next
iteration's elites degenerate in turn, and the search collapses (the linear
limit state in ``D = 1000`` at ``1e-6``: no hit, or 50% errors, at 100,000
calls; BENCHMARKS.md). Splitting's particles need no weights, so ``n`` is the
particles' effective number, and the shift can include coordinates a CE box
leaves alone (``shift="all"``: the learned drivers' 404-d ``xi``, of which the
particles show few to matter). Where many coordinates each matter a little,
no coordinate selection helps; the shrunk shift over all of them leaves noise
``D / n_eff`` in the weights' second moment, a factor of about
``exp(c^2 D / n_eff)`` (about ``e^5`` for that linear limit state with 7,142
particles per level: relative RMSE 0.17). Where ``f`` falls along one
direction, the shift along its fitted slope leaves ``1 / n_eff``.

Replicates
----------
Steps 1-2 run ``replicates`` times, independently, with ``n_particles /
replicates`` particles each (the same calls of ``f`` as one run of
``n_particles``), and step 3 fits one proposal to the particles of them all.
A failure region one replicate's levels never reach (a region that holds most
of ``p`` but whose intermediate levels are rarer than another's) is then in
the proposal if another reached it. Replicates whose own estimates differ
beyond their errors
(:func:`~avrisk.rare.splitting_replicates.replicates_disagree`, in
``details["replicates_disagree"]``, each replicate's estimate in
``details["replicates"]``) show a search that can miss a region; the run
says caution only when its importance-sampling estimate lies below every
replicate's, beyond both errors (:meth:`doubts`): a proposal can miss mass
the particles found, not add mass. One run cannot see a region no replicate
reached. A replicate whose ``max_levels`` sets end above ``gamma`` (its
levels followed a mechanism that does not end in the event) runs again,
fresh, with twice its particles, up to ``regrow`` times and within
``max_calls`` (*Regrowth* in :mod:`avrisk.rare.splitting_replicates`); the
runs it replaces are in the record but in no estimate. One that still ends
above ``gamma`` is left out of the fit and the run says caution; when none
reaches ``gamma``, the proposal is fitted to the deepest sets they found and
its sample answers, a bound where it has no hit, with caution.

The answer
----------
The importance-sampling estimate, unless the particles say beforehand that
the levels' own product (the replicates' mean) will be more precise;
``details["answer"]`` says which, and both are kept in ``details``
(:mod:`avrisk.rare.splitting_is_answer` says how and why).

:class:`SplittingImportanceSampling` is registered as ``"splitting_is"``;
:func:`splitting_is` is the top-level function.

References
----------
S.-K. Au, J. L. Beck. "A new adaptive importance sampling scheme for
reliability calculations." Structural Safety 21, 1999 (importance densities
from conditional samples of the failure domain).
S. Geyer, I. Papaioannou, D. Straub. "Cross entropy-based importance sampling
using Gaussian densities revisited." Structural Safety 76, 2019.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from avrisk.rare.black_box import estimate
from avrisk.rare.chain_moments import uninformed_coordinates
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    DiagnosticTable,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.particle_fit import THRESHOLDS, ParticleFit, particle_proposal
from avrisk.rare.particle_shifts import slope_direction
from avrisk.rare.problem import FINAL_STAGE, BatchFunction, RareEventProblem
from avrisk.rare.results import Estimate
from avrisk.rare.splitting import SubsetSimulation
from avrisk.rare.splitting_is_answer import (
    SAMPLED_KEYS,
    answer_doubts,
    importance_stage,
    levels_more_precise,
)
from avrisk.rare.splitting_is_settings import SplittingISSettings
from avrisk.rare.splitting_is_tables import importance_sampling_tables
from avrisk.rare.splitting_levels import SplittingState, levels_estimate
from avrisk.rare.splitting_moves import (
    MovedSet,
    move_chains,
    moves_after,
    refreshed,
)
from avrisk.rare.splitting_precision import MoreReplicates, more_replicates
from avrisk.rare.splitting_replicates import (
    ReplicatesState,
    combined_levels,
    pooled_chains,
    replicates_record,
)

__all__ = [
    "SplittingISSettings",
    "SplittingImportanceSampling",
    "splitting_is",
]

#: Extra key of the fit's generator (k-means++ seeding), so that it draws no
#: chunk's stream.
FIT_STREAM = 0x736973


@register_estimator
class SplittingImportanceSampling(SubsetSimulation):
    """Subset simulation, then importance sampling from its particles (module doc)."""

    name = "splitting_is"
    label = "splitting + IS"
    Settings: type[SplittingISSettings] = SplittingISSettings
    weighted = True
    decomposable = True
    settings: SplittingISSettings

    @staticmethod
    def doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
        """Replicates that ran out of levels, or an answer the other estimate belies.

        :func:`~avrisk.rare.splitting_is_answer.answer_doubts`: which doubts
        count depends on which estimate answers (*The answer*).
        """
        return answer_doubts(estimate, gamma)

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """A set of the levels (:meth:`SubsetSimulation.stage_label`), or after them.

        After the last set: ``"the moves at gamma"``, the chains whose states
        the proposal was fitted to; the final stage: ``"the
        importance-sampling stage"``.
        """
        if stage == FINAL_STAGE:
            return "the importance-sampling stage"
        history = estimate.get("history") or [{}]
        if stage > history[-1].get("last_stage", stage):
            return "the moves at gamma"
        return SubsetSimulation.stage_label(estimate, stage)

    def budget_not_redrawn(self) -> int:
        """All but the final stage, a fresh draw of the fitted proposal."""
        return self.budget() - self.settings.n_final

    def describe(self) -> str:
        """``"subset simulation, 2,000 particles per level, p0 0.1, then IS ..."``."""
        s = self.settings
        refresh = f", {s.refresh_rounds} refresh rounds" if s.refresh_rounds else ""
        return (
            f"{super().describe()}{refresh}, then IS {s.n_final:,} "
            f"({s.n_components} components, defensive {s.defensive:g})"
        )

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """The levels, the proposal fitted to the particles, and the cross-check.

        The levels as subset simulation's; the proposal's components, its
        shift (``"coords"``: fitted per coordinate; ``"slope"``: along ``f``'s
        slope), the coordinates it shifts, the threshold that chose them
        [standard errors], the acceptance of the moves at ``gamma`` that made its
        particles, and its samples' hits, ESS and Pareto k at ``gamma``; then,
        per threshold, the importance-sampling estimate beside subset
        simulation's own of the same run (``details["splitting"]``).
        """
        levels = SubsetSimulation.diagnostics(estimate)
        if "splitting" not in (estimate.get("details") or {}):
            return levels
        return [*levels, *importance_sampling_tables(estimate)]

    def finalize(  # type: ignore[override]
        self,
        state: ReplicatesState,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> Estimate:
        """Move the replicates' hits at ``gamma``, fit one proposal, sample it.

        The proposal is fitted to every replicate's particles at once, and
        sampled ``n_final`` times. With no hit at ``gamma`` in any replicate
        (a plateau no particle left), subset simulation's bound is the answer
        (*Plateaus* in :mod:`avrisk.rare.splitting_levels`). The fit's
        generator comes from the run seed, so a resumed run fits the same
        proposal and replays the recorded final stage.
        """
        reached = state.reached()
        own = [levels_estimate(r, problem, n, genealogy=True) for r, n in reached]
        if reached:
            combined = combined_levels(own, problem, sum(n for _, n in reached))
            with_hits = [
                (r, n) for (r, n), e in zip(reached, own, strict=True) if e.n_hits
            ]
            if not with_hits:  # no particle to fit: the levels' bound
                return dataclasses.replace(combined, method="splitting_is")
        else:  # none reached gamma: sample from the deepest sets they found
            with_hits = list(zip(state.all, state.sizes, strict=True))
            deepest = [levels_estimate(r, problem, n) for r, n in with_hits]
            combined = combined_levels(deepest, problem, sum(state.sizes))
        s = self.settings
        moves, refreshes = _refreshed_at_gamma(
            _moves_at_gamma(with_hits, state.current.n_stages, problem, context, s),
            with_hits,
            problem,
            context,
            s.refresh_rounds,
        )
        fitted = _fitted_proposal(moves, with_hits, problem, context, s)
        n_evals = state.current.n_evals + sum(m.n_calls for m in moves)
        more = MoreReplicates(state, own, combined, n_evals, moves[-1].n_stages, 0)
        more = self._more_replicates(more, fitted, problem, context)
        state, own, combined, n_evals = more[:4]
        # the levels' answer, unless a replicate ran out of levels
        levels = None if any(r.exhausted for r in state.all) else combined
        stage, sampled, from_levels = importance_stage(
            fitted, problem, context, s.n_final, n_evals, levels
        )
        return Estimate(
            method="splitting_is",
            gamma=problem.gamma,
            by_gamma=dict(combined.by_gamma) if from_levels else sampled,
            n_evals=n_evals + stage.values.size,
            proposal=fitted.proposal,
            stopped_by=stage.stopped_by or "budget",
            details={
                **combined.details,
                **_fit_record(combined, moves, fitted),
                **({"refreshed": refreshes} if s.refresh_rounds else {}),
                "splitting": {  # none where no replicate reached gamma
                    str(g): {"p": e.p, "ci": list(e.ci)}
                    for g, e in combined.by_gamma.items()
                    if reached
                },
                "importance_sampling": {
                    str(g): {k: e.to_dict()[k] for k in SAMPLED_KEYS}
                    for g, e in sampled.items()
                },
                "answer": "splitting" if from_levels else "importance_sampling",
                "held_out_uncovered": fitted.held_out.uncovered,
                "held_out_covered_weight": fitted.held_out.covered_mean_weight,
                **replicates_record(state, own, s.replicates + more.added),
                **({"replicates_added": more.added} if more.added else {}),
            },
        )

    def _more_replicates(
        self,
        start: MoreReplicates,
        fitted: ParticleFit,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> MoreReplicates:
        """The replicates, more of them where the levels will answer imprecisely.

        Where the levels will answer, as
        :func:`~avrisk.rare.splitting_is_answer.importance_stage` decides
        (no replicate out of levels, so every one reached ``gamma``, and the
        particles predict the levels more precise), and the settings allow
        (``more_replicates``):
        :func:`~avrisk.rare.splitting_precision.more_replicates`, within the
        budget less the final stage.
        """
        s = self.settings
        if not (
            s.more_replicates
            and not any(r.exhausted for r in start.state.all)
            and levels_more_precise(fitted.held_out, start.combined.main, s.n_final)
        ):
            return start
        room = self.budget() - start.n_evals - s.n_final
        levels = self.levels(start.state.sizes[0])
        return more_replicates(levels, start, problem, context, room, s.replicates)


def _moves_at_gamma(
    with_hits: list[tuple[SplittingState, int]],
    first_stage: int,
    problem: RareEventProblem,
    context: EstimationContext,
    settings: SplittingISSettings,
) -> list[MovedSet]:
    """Each replicate's chains moved once more at ``gamma``: the particles to fit.

    Each replicate ``(state, n)`` moves ``n`` states on stages of its own,
    numbered from ``first_stage`` (after every replicate's levels) in turn,
    ``settings.gamma_moves()`` proposals per kept state (times its
    ``correlated_factor()`` after correlated chains:
    :func:`~avrisk.rare.splitting_moves.moves_after`).
    """
    moves, stage = [], first_stage
    n_moves, correlated_moves = settings.gamma_moves(), settings.correlated_factor()
    for r, n in with_hits:
        per_state = moves_after(r.sets[-1], n_moves, correlated_moves)
        moves.append(
            move_chains(r._replace(n_stages=stage), problem, context, per_state, n)
        )
        stage = moves[-1].n_stages
    return moves


def _refreshed_at_gamma(
    moves: list[MovedSet],
    with_hits: list[tuple[SplittingState, int]],
    problem: RareEventProblem,
    context: EstimationContext,
    rounds: int,
) -> tuple[list[MovedSet], list[dict[str, float]]]:
    """The moved particles after ``rounds`` refreshes of what they do not inform.

    Each round draws afresh the coordinates that all replicates' particles
    pooled leave within the sparsest of ``THRESHOLDS`` widened standard
    errors of ``N(0, 1)`` (:func:`~avrisk.rare.chain_moments.uninformed_coordinates`),
    one proposal per particle below its replicate's last level
    (:func:`~avrisk.rare.splitting_moves.refreshed`), on stages numbered on
    from the moves'. None is made where no coordinate is uninformed, or every
    one (the widened errors of an event that moves most coordinates; a fresh
    draw of every coordinate is a draw of ``P0``, not a refresh). Returns the
    particles and, per round, the coordinates drawn and the share accepted
    (``details["refreshed"]``).
    """
    record = []
    for _ in range(rounds):
        z = np.concatenate([m.z for m in moves])
        block = uninformed_coordinates(
            z, pooled_chains([m.values for m in moves]), THRESHOLDS[0]
        )
        if not block.any() or block.all():  # all: a fresh draw of P0, no refresh
            break
        stage, accepted, fresh = moves[-1].n_stages, 0.0, []
        for m, (r, _) in zip(moves, with_hits, strict=True):
            m, share = refreshed(
                m._replace(n_stages=stage), r.sets[-1].level, block, problem, context
            )
            fresh.append(m)
            accepted += share * len(m.z)
            stage = m.n_stages
        moves = fresh
        record.append(
            {"coordinates": int(block.sum()), "acceptance": accepted / len(z)}
        )
    return moves, record


def _fitted_proposal(
    moves: list[MovedSet],
    with_hits: list[tuple[SplittingState, int]],
    problem: RareEventProblem,
    context: EstimationContext,
    settings: SplittingISSettings,
) -> ParticleFit:
    """The proposal fitted to every replicate's moved particles at once.

    The shift along ``f``'s slope is fitted to the replicates' last sets
    (their particles and values); the fit's generator comes from the run
    seed (``FIT_STREAM``), so a resumed run fits the same proposal.
    """
    rng = np.random.default_rng(
        np.random.SeedSequence([context.seed], spawn_key=(FIT_STREAM,))
    )
    z = np.concatenate([m.z for m in moves])
    chain = pooled_chains([m.values for m in moves])
    slope = slope_direction(
        np.concatenate([r.z for r, _ in with_hits]),
        np.concatenate([r.sets[-1].flat for r, _ in with_hits]),
    )
    return particle_proposal(z, chain, problem.base, settings, rng, slope)


def _fit_record(
    combined: Estimate, moves: list[MovedSet], fitted: ParticleFit
) -> dict[str, Any]:
    """The moves' failures and acceptance at ``gamma``, and the fit's choices."""
    return {
        "n_failed": combined.details["n_failed"]
        + sum(m.n_failed for m in moves),  # the moves at gamma too
        "fit_acceptance": float(
            np.mean(
                [m.acceptance for m in moves if not np.isnan(m.acceptance)] or [np.nan]
            )
        ),
        "n_components": fitted.proposal.n_components,
        "informative_threshold": fitted.threshold,
        "along_slope": fitted.along_slope,
        "n_shifted": fitted.n_shifted,
        "fitted_variances": fitted.variances,
    }


def splitting_is(
    f: BatchFunction, base: ExponentialFamily, gamma: float, **options: Any
) -> Estimate:
    """Splitting + IS: ``estimate("splitting_is", f, base, gamma, **options)``."""
    return estimate("splitting_is", f, base, gamma, **options)
