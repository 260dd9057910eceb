"""Cross-entropy adaptive importance sampling (O'Kelly et al. 2018, Algorithm 1).

For ``k = 0 .. K-1``, with proposal ``P_theta_k`` (``theta_0`` = base):

1. draw ``N`` samples ``X_i ~ P_theta_k`` and evaluate ``f_i = f(X_i)``;
2. ``gamma_k = max(gamma, rho-quantile of f)``;
3. ``D = sum_i w_i 1{f_i <= gamma_k} T(X_i) / sum_i w_i 1{f_i <= gamma_k}`` with
   ``log w_i = log p0(X_i) - log p_theta_k(X_i)`` (self-normalised in log space);
4. ``theta_{k+1} = argmax_{theta in box} theta^T m - A(theta)`` with
   ``m = alpha D + (1 - alpha) grad A(theta_k)`` (exact projection per family);
5. remember the ``theta_k`` with the lowest ``rho``-quantile (``select=
   "quantile"``, the paper's rule; see :data:`SELECTION_RULES` for another).

The estimate comes from ``n`` fresh samples of the remembered proposal:
``p_hat = mean(w_i 1{f_i <= gamma})``, unbiased for ``P0(f <= gamma)``.

:class:`CrossEntropy` is the method behind the engine's estimator protocol
(:mod:`avrisk.rare.estimator`): its ``init`` / ``step`` pair carries everything
the next iteration needs in a :class:`CEState` and diagnostics in a
:class:`CEInfo`, so a driver can checkpoint between iterations. It is
registered as ``"ce"`` and, with a defensive final stage of 10% by default, as
``"defensive"``. :func:`cross_entropy` is the top-level function.

References
----------
M. O'Kelly, A. Sinha, H. Namkoong, J. Duchi, R. Tedrake. "Scalable end-to-end
autonomous vehicle testing via rare-event simulation." NeurIPS 2018.
R. Y. Rubinstein, D. P. Kroese. The Cross-Entropy Method. Springer, 2004.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Annotated, Any, Literal, NamedTuple

import numpy as np
from pydantic import Field

from avrisk.rare.black_box import estimate
from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.estimator import (
    DiagnosticTable,
    EstimationContext,
    EstimatorSettings,
    no_doubts,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.final_stage import Advice, weighted_stage_estimates
from avrisk.rare.problem import (
    FINAL_STAGE,
    BatchFunction,
    RareEventProblem,
)
from avrisk.rare.results import CEInfo, Estimate, SearchConvergence
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
    """Steps 2-3 of the module docstring: the level ``gamma_k`` and its elite.

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


#: The types of the settings that the variants of :class:`CESettings` give
#: other defaults (:class:`~avrisk.rare.mixture.MixtureSettings`): their
#: constraints, declared once.
EliteLevel = Annotated[
    float, Field(gt=0.0, lt=1.0, description="Elite quantile level.")
]
SearchIterations = Annotated[int, Field(ge=0, description="Search iterations.")]
ShareOfP0 = Annotated[float, Field(ge=0.0, lt=1.0)]


class CESettings(EstimatorSettings):
    """Settings of cross-entropy importance sampling (the paper's names).

    Attributes
    ----------
    rho : float, default=0.01
        Quantile level defining the elite samples, in (0, 1).
    alpha : float, default=0.8
        Smoothing of the mean-parameter update, in (0, 1].
    n_per_iter : int, default=5000
        Samples per search iteration.
    n_iter : int, default=100
        Search iterations ``K`` (0: the final stage samples the base).
    n_final : int, default=100000
        Fresh samples of the chosen proposal for the estimate.
    select : {"quantile", "variance"}, default="quantile"
        Rule choosing the final proposal among the iterates
        (:data:`SELECTION_RULES`); ``"quantile"`` is the paper's.
    defensive : float, default=0.0
        Fraction ``lam`` in [0, 1) of the final stage drawn from the base
        instead of the chosen proposal (a defensive mixture,
        :mod:`avrisk.rare.defensive`): every weight is then at most
        ``1 / lam``, so a proposal that misses part of the event, or has
        heavy-tailed weights, cannot make the estimate or its standard error
        collapse. 0 (the paper's): the proposal alone.
    space : {"natural", "standard"}, default="natural"
        Where the proposals live (:func:`search_structure`): the base's own
        family at other parameters (the paper's), or mean shifts of the base's
        standard normals (:class:`~avrisk.rare.families.StandardSpaceShift`),
        whose weights have finite variance however far the search goes.
    """

    OMIT_IF_DEFAULT = ("defensive", "space")

    rho: EliteLevel = 0.01
    alpha: float = Field(0.8, gt=0.0, le=1.0, description="Smoothing of the update.")
    n_per_iter: int = Field(5000, ge=1, description="Samples per search iteration.")
    n_iter: SearchIterations = 100
    n_final: int = Field(100_000, ge=1, description="Samples of the final stage.")
    select: Literal["quantile", "variance"] = Field(
        "quantile", description="Rule choosing the final proposal (SELECTION_RULES)."
    )
    defensive: ShareOfP0 = Field(
        0.0, description="Share of the final stage drawn from P0 (weights <= 1/share)."
    )
    space: Literal["natural", "standard"] = Field(
        "natural",
        description="Proposals: the base's family ('natural') or mean shifts of "
        "its standard normals ('standard').",
    )


def search_structure(base: ExponentialFamily, space: str) -> ExponentialFamily:
    """The family whose members a CE search proposes, at ``P0``.

    ``"natural"``: ``base`` itself; ``"standard"``: ``StandardSpaceShift(base)``
    (the same distribution, parametrised by a shift of its standard normals).
    """
    return StandardSpaceShift(base) if space == "standard" else base


class DefensiveCESettings(CESettings):
    """CE with a defensive final stage: ``defensive`` must be above 0."""

    OMIT_IF_DEFAULT = ()

    defensive: float = Field(
        0.1,
        gt=0.0,
        lt=1.0,
        description="Share of the final stage drawn from P0 (weights <= 1/share).",
    )


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
) -> Estimate:
    """The estimate of a CE search: ``n_final`` fresh samples of ``sampled``.

    ``sampled`` is the best proposal ``state.best`` or a defensive mixture of
    it; the final stage may end early by the context's stopping rule.
    """
    stage = context.stage(
        problem, sampled, n_final, FINAL_STAGE, final_after=state.n_evals
    )
    return Estimate(
        method=method,
        gamma=problem.gamma,
        by_gamma=weighted_stage_estimates(stage, problem.thresholds, SEARCH_ADVICE),
        n_evals=state.n_evals + stage.values.size,
        proposal=state.best,
        best_iteration=None if state.best_iteration < 0 else state.best_iteration,
        stopped_by=stage.stopped_by or "budget",
    )


def search_diagnostics(
    title: str,
    estimate: dict[str, Any],
    step: str = "iteration",
    extra: tuple[tuple[str, str], ...] = (),
) -> list[DiagnosticTable]:
    """A CE search's trajectory per iteration: levels, quantiles, hits, ESS.

    ``step`` names the iteration column; ``extra`` adds ``(column name,
    history key)`` pairs after the others.
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
        )
    ]


def search_stage_label(stage: int, step: str = "iteration") -> str:
    """A CE search's name of ``stage``: ``"iteration 3"`` (stage 4), or the final one.

    ``step`` names the iterations as :func:`search_diagnostics` does.
    """
    return "the final stage" if stage == FINAL_STAGE else f"{step} {stage - 1}"


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


@register_estimator
class CrossEntropy:
    """Cross-entropy importance sampling (module docstring) as an Estimator."""

    name = "ce"
    label = "cross-entropy"
    Settings: type[CESettings] = CESettings
    weighted = True
    decomposable = True
    budget_is_bound = False

    def __init__(self, settings: CESettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """Search iterations times their samples, plus the final stage."""
        s = self.settings
        return s.n_iter * s.n_per_iter + s.n_final

    def budget_not_redrawn(self) -> int:
        """0: every sample is a fresh draw of its stage's proposal."""
        return 0

    def describe(self) -> str:
        """``"CE 20x5,000 + 100,000"`` (and the defensive share)."""
        s = self.settings
        text = f"CE {s.n_iter}x{s.n_per_iter:,} + {s.n_final:,}"
        return text + (f", defensive {s.defensive:g}" if s.defensive else "")

    def init(self, problem: RareEventProblem) -> CEState:
        """Before the first iteration: the proposal is the base distribution."""
        start = search_structure(problem.base, self.settings.space)
        return CEState(start, 0, start, (math.inf,), -1, 0)

    def done(self, state: CEState) -> bool:
        """After ``n_iter`` iterations."""
        return state.iteration >= self.settings.n_iter

    def step(
        self, state: CEState, problem: RareEventProblem, context: EstimationContext
    ) -> tuple[CEState, CEInfo]:
        """One cross-entropy iteration (steps 1-5 of the module docstring).

        The samples of iteration ``k`` come from stage ``k + 1`` of the run
        seed, so an iteration re-run from a checkpointed state gives the same
        result. Samples that failed to evaluate count as safe in the search
        (they only steer the proposal; the final stage brackets them).
        """
        s = self.settings
        stage = state.iteration + 1
        proposal = state.proposal
        result = context.stage(problem, proposal, s.n_per_iter, stage, keep_stats=True)
        assert result.stats is not None
        level = search_level(result, s.rho, problem.gamma, state.iteration)
        target = level.elite_weights @ result.stats[level.elite]
        m = s.alpha * target + (1.0 - s.alpha) * proposal.mean_param()
        n_evals = state.n_evals + s.n_per_iter
        info = CEInfo(
            iteration=state.iteration,
            gamma_k=level.gamma_k,
            quantile=level.quantile,
            ess=level.elite_ess,
            n_elite=int(level.elite.sum()),
            n_hits=level.n_hits,
            n_evals=n_evals,
            rel_var=level.rel_var,
        )
        score = SELECTION_RULES[s.select](level)
        better = score < state.best_score
        new_state = CEState(
            proposal=proposal.project(m),
            iteration=stage,
            best=proposal if better else state.best,
            best_score=score if better else state.best_score,
            best_iteration=state.iteration if better else state.best_iteration,
            n_evals=n_evals,
        )
        return new_state, info

    def finalize(
        self, state: CEState, problem: RareEventProblem, context: EstimationContext
    ) -> Estimate:
        """Fresh samples of the best proposal (or its defensive mixture)."""
        s = self.settings
        sampled = (
            DefensiveMixture(state.best, problem.base, s.defensive)
            if s.defensive
            else state.best
        )
        return search_final_estimate(
            "cross_entropy", state, sampled, s.n_final, problem, context
        )

    def progress(self, info: CEInfo) -> str:
        """``"iter 3: gamma_k=0.21 hits=12 ESS=40"``."""
        return (
            f"iter {info.iteration}: gamma_k={info.gamma_k:.3g} "
            f"hits={info.n_hits} ESS={info.ess:.0f}"
        )

    def checkpoint(self, state: CEState, infos: Sequence[CEInfo]) -> dict[str, Any]:
        """The proposals and the iterations so far (for inspection and reports)."""
        return search_checkpoint(state, infos)

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """The search trajectory: levels, quantiles, hits and ESS per iteration."""
        return search_diagnostics("Cross-entropy search", estimate, "CE iteration")

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """``"CE iteration 3"`` (stage 4), or ``"the final stage"``."""
        return search_stage_label(stage, "CE iteration")

    #: Whether the search reached a threshold and held it.
    convergence = staticmethod(search_convergence)
    doubts = staticmethod(no_doubts)


@register_estimator
class DefensiveCrossEntropy(CrossEntropy):
    """CE whose final stage is a defensive mixture with ``P0`` (Hesterberg 1995)."""

    name = "defensive"
    label = "cross-entropy, defensive"
    Settings = DefensiveCESettings


def cross_entropy(
    f: BatchFunction, base: ExponentialFamily, gamma: float, **options: Any
) -> Estimate:
    """Cross-entropy: ``estimate("ce", f, base, gamma, **options)``."""
    return estimate("ce", f, base, gamma, **options)
