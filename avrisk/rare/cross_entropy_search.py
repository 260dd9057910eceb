"""The steps of a cross-entropy search that plain and mixture CE share.

Plain cross-entropy (:mod:`avrisk.rare.cross_entropy`, whose docstring states
the algorithm) moves one member of the base family down the levels; mixture
cross-entropy (:mod:`avrisk.rare.mixture`) moves a mixture of them. Both
iterate the same way, and the parts that do not depend on the kind of
proposal live here:

* :class:`CEState`: what the next iteration needs (the proposal, the best one
  so far, the calls of ``f``), so a driver can checkpoint between iterations;
* :func:`search_level`: an iteration's level ``gamma_k`` (the
  ``rho``-quantile of its ``n`` values of ``f``, never below ``gamma``) and
  its elite with their self-normalised weights ``p0 / q``, shape
  (n_elite,);
* :data:`SELECTION_RULES`: which evaluated proposal the final stage samples;
* :func:`search_structure`: the family searched, the base's own or mean
  shifts of its standard normals;
* what a search records and reports: its checkpoint
  (:func:`search_checkpoint`), the estimate of its final stage
  (:func:`search_final_estimate`), its trajectory as a diagnostic table
  (:func:`search_diagnostics`), its stage labels (:func:`search_stage_label`)
  and whether it reached a threshold (:func:`search_convergence`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import DiagnosticTable
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.final_stage import Advice, weighted_stage_estimates
from avrisk.rare.problem import FINAL_STAGE, RareEventProblem
from avrisk.rare.proposal_audit import audit_bound, audit_proposal, audit_table
from avrisk.rare.results import Estimate, SearchConvergence
from avrisk.rare.stages import StageResult
from avrisk.rare.weights import (
    kish_ess,
    normalized_weights,
    weighted_mean_and_stderr,
)


class CEState(NamedTuple):
    """What the next cross-entropy iteration needs (plain or mixture CE).

    Attributes
    ----------
    proposal : ExponentialFamily or MixtureProposal
        Proposal to sample at the next iteration.
    iteration : int
        Iterations completed.
    best : ExponentialFamily or MixtureProposal
        Evaluated proposal with the best selection score so far.
    best_score : tuple of float
        That score, smaller is better (``(inf,)`` before the first iteration).
    best_iteration : int
        Iteration that sampled ``best`` (-1: none yet, ``best`` is the base).
    n_evals : int
        Calls of ``f`` so far.
    """

    proposal: Any
    iteration: int
    best: Any
    best_score: tuple[float, ...]
    best_iteration: int
    n_evals: int


#: Hits an iterate needs before the ``"variance"`` rule trusts its estimate.
MIN_HITS_FOR_VARIANCE = 10


class SearchLevel(NamedTuple):
    """The level of one search iteration and what its samples say at it.

    Attributes
    ----------
    quantile : float
        ``rho``-quantile of ``f`` over the iteration's samples.
    gamma_k : float
        Level of the update, ``max(gamma, quantile)``.
    elite : ndarray of bool, shape (n,)
        Samples with ``f <= gamma_k`` (failed samples count as safe).
    elite_weights : ndarray of shape (n_elite,)
        Self-normalised likelihood ratios ``p0 / q`` of the elite samples.
    elite_ess : float
        Kish effective sample size of those weights.
    n_hits : int
        Samples with ``f <= gamma``.
    rel_var : float
        Relative variance per sample of importance sampling with the sampled
        proposal, ``Var(w 1{f <= gamma}) / p^2``, from these samples (``inf``
        without hits).
    """

    quantile: float
    gamma_k: float
    elite: np.ndarray
    elite_weights: FloatArray
    elite_ess: float
    n_hits: int
    rel_var: float


def search_level(
    stage: StageResult, rho: float, gamma: float, iteration: int
) -> SearchLevel:
    """Steps 2-3 of CE (:mod:`avrisk.rare.cross_entropy`): ``gamma_k`` and its elite.

    Samples that failed to evaluate count as safe (they only steer the search;
    the final stage brackets them).

    Parameters
    ----------
    stage : StageResult
        The ``n`` evaluated samples of search iteration ``iteration``.
    rho : float
        Quantile level of the elite, in (0, 1).
    gamma : float
        Threshold of the event.
    iteration : int
        Index of the iteration (for the error message).

    Raises
    ------
    FloatingPointError
        If every elite sample has zero base density (no weight to fit to).
    """
    values = np.where(stage.failed, np.inf, stage.values)
    log_w = stage.log_w
    quantile = float(np.quantile(values, rho, method="inverted_cdf"))
    gamma_k = max(gamma, quantile)
    elite = values <= gamma_k
    if not np.isfinite(log_w[elite]).any():
        raise FloatingPointError(
            f"iteration {iteration}: every elite sample has zero base density"
        )
    hits = values <= gamma
    p_k, se_k = weighted_mean_and_stderr(log_w, hits)
    return SearchLevel(
        quantile=quantile,
        gamma_k=gamma_k,
        elite=elite,
        elite_weights=normalized_weights(log_w[elite]),
        elite_ess=kish_ess(log_w[elite]),
        n_hits=int(np.count_nonzero(hits)),
        rel_var=values.size * (se_k / p_k) ** 2 if p_k > 0 else math.inf,
    )


def _quantile_score(level: SearchLevel) -> tuple[float, ...]:
    return (level.quantile,)


def _variance_score(level: SearchLevel) -> tuple[float, ...]:
    if level.n_hits >= MIN_HITS_FOR_VARIANCE:
        return (-math.inf, level.rel_var)
    return (level.quantile, math.inf)


#: How the proposal of the final stage is chosen among the evaluated iterates,
#: from their :class:`SearchLevel` (smaller score is better).
#: ``"quantile"``: lowest ``rho``-quantile (paper). Once the quantiles fall below
#: ``gamma`` this favours proposals that overshoot into the event, which in high
#: dimension can have degenerate weights. ``"variance"``: among iterates with at
#: least ``MIN_HITS_FOR_VARIANCE`` hits, the lowest estimated relative variance
#: (``SearchLevel.rel_var``); before any has, the lowest quantile.
SELECTION_RULES: dict[str, Callable[[SearchLevel], tuple[float, ...]]] = {
    "quantile": _quantile_score,
    "variance": _variance_score,
}


def search_structure(base: ExponentialFamily, space: str) -> ExponentialFamily:
    """The family whose members a CE search proposes, at ``P0``.

    ``"natural"``: ``base`` itself; ``"standard"``: ``StandardSpaceShift(base)``
    (the same distribution, parametrised by a shift of its standard normals).
    """
    return StandardSpaceShift(base) if space == "standard" else base


def search_checkpoint(state: CEState, infos: Sequence[Any]) -> dict[str, Any]:
    """JSON record of a cross-entropy search: its proposals and iterations."""
    return {
        "iterations_done": state.iteration,
        "n_evals": state.n_evals,
        "proposal": state.proposal.to_dict(),
        "best": state.best.to_dict(),
        "best_iteration": state.best_iteration,
        "history": [h.to_dict() for h in infos],
    }


def search_budget(settings: Any) -> int:
    """Calls of a CE search's run: its iterations, its final stage, its audit's bound.

    ``settings``: a :class:`~avrisk.rare.cross_entropy.CESettings` (or a
    variant's).
    """
    s = settings
    return s.n_iter * s.n_per_iter + s.n_final + audit_bound(s.audit())


#: Remedies of a CE search's unreliable final stage, in its settings' names.
SEARCH_ADVICE = Advice(
    no_hit="raise n_final, or the search (n_iter, n_per_iter)",
    degenerate="the proposal is degenerate: raise n_per_iter or rho, or see "
    "Estimate.history",
    heavy_tail="raise n_per_iter and n_final, or compare runs with other seeds",
)


def search_final_estimate(
    method: str,
    state: CEState,
    sampled: Any,
    n_final: int,
    problem: RareEventProblem,
    context: EstimationContext,
    audit_particles: int = 0,
) -> Estimate:
    """The estimate of a CE search: ``n_final`` fresh samples of ``sampled``.

    ``sampled`` is the best proposal ``state.best`` or a defensive mixture of
    it; the final stage may end early by the context's stopping rule. With
    ``audit_particles``, an independent subset simulation then checks that
    ``sampled`` draws where the event is (:mod:`avrisk.rare.proposal_audit`,
    ``details["audit"]``; its calls are in ``n_evals``), on the stages after
    the search's.
    """
    stage = context.stage(
        problem, sampled, n_final, FINAL_STAGE, final_after=state.n_evals
    )
    estimate = Estimate(
        method=method,
        gamma=problem.gamma,
        by_gamma=weighted_stage_estimates(stage, problem.thresholds, SEARCH_ADVICE),
        n_evals=state.n_evals + stage.values.size,
        proposal=state.best,
        best_iteration=None if state.best_iteration < 0 else state.best_iteration,
        stopped_by=stage.stopped_by or "budget",
    )
    if not audit_particles:
        return estimate
    audit = audit_proposal(
        sampled,
        estimate,
        stage.values.size,
        problem,
        context,
        particles=audit_particles,
        after_stage=state.iteration,
    )
    return replace(
        estimate,
        n_evals=estimate.n_evals + audit["n_calls"],
        details={**(estimate.details or {}), "audit": audit},
    )


def search_diagnostics(
    title: str,
    estimate: dict[str, Any],
    step: str = "iteration",
    extra: tuple[tuple[str, str], ...] = (),
) -> list[DiagnosticTable]:
    """A CE search's trajectory per iteration: levels, quantiles, hits, ESS.

    Then its audit's table, where it has one
    (:func:`~avrisk.rare.proposal_audit.audit_table`). ``step`` names the
    iteration column; ``extra`` adds ``(column name, history key)`` pairs
    after the others.
    """
    history = estimate.get("history") or []
    if not history:
        return []
    keys = (
        (step, "iteration"),
        ("rho-quantile of f", "quantile"),
        ("gamma_k", "gamma_k"),
        ("samples with f <= gamma", "n_hits"),
        ("elite ESS", "ess"),
        *extra,
    )
    rows = [tuple(h[key] for _, key in keys) for h in history]
    return [
        DiagnosticTable(
            title,
            tuple(name for name, _ in keys),
            rows,
            lines=("rho-quantile of f", "gamma_k"),
            bars="samples with f <= gamma",
            note=(
                "Each iteration draws samples from the current proposal, takes "
                "the rho-quantile of their f as its level gamma_k (never below "
                "gamma) and refits the proposal to the samples at or below it "
                "(the elite, with their importance weights); the search has "
                "found the event once gamma_k reaches gamma. Elite ESS: how "
                "many equally weighted samples the weighted elite is worth."
            ),
        ),
        *audit_table(estimate),
    ]


def search_stage_label(
    estimate: dict[str, Any], stage: int, step: str = "iteration"
) -> str:
    """A CE search's name of ``stage``: ``"iteration 3"`` (stage 4), or another.

    ``step`` names the iterations as :func:`search_diagnostics` does; the
    stages after the search's are the audit's
    (:mod:`avrisk.rare.proposal_audit`).
    """
    if stage == FINAL_STAGE:
        return "the final stage"
    if stage > len(estimate.get("history") or ()):
        return "the audit's subset simulation"
    return f"{step} {stage - 1}"


def search_convergence(
    estimate: dict[str, Any], gamma: float
) -> SearchConvergence | None:
    """Whether a CE search reached ``gamma`` and held it (:class:`SearchConvergence`).

    Parameters
    ----------
    estimate : dict
        A summary's ``estimate`` (:meth:`Estimate.to_dict`): its ``history``
        holds each iteration's ``quantile``.
    gamma : float
        The threshold asked about (the run's, or a test threshold).

    Returns
    -------
    SearchConvergence or None
        None without iterations (``n_iter = 0``: the final stage samples
        ``P0``; nothing was searched).
    """
    quantiles = [h["quantile"] for h in estimate.get("history") or []]
    if not quantiles:
        return None
    # A quantile recorded as null was not finite (every sample failed): inf.
    levels = [math.inf if q is None else float(q) for q in quantiles]
    reached = next((k for k, q in enumerate(levels) if q <= gamma), None)
    return SearchConvergence(gamma, len(levels), reached, min(levels), levels[-1])
