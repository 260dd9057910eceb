"""Cross-entropy adaptive importance sampling (O'Kelly et al. 2018, Algorithm 1).

For ``k = 0 .. K-1``, with proposal ``P_theta_k`` (``theta_0`` = base):

1. draw ``N`` samples ``X_i ~ P_theta_k`` and evaluate ``f_i = f(X_i)``;
2. ``gamma_k = max(gamma, rho-quantile of f)``;
3. ``D = sum_i w_i 1{f_i <= gamma_k} T(X_i) / sum_i w_i 1{f_i <= gamma_k}`` with
   ``log w_i = log p0(X_i) - log p_theta_k(X_i)`` (self-normalised in log space);
4. ``theta_{k+1} = argmax_{theta in box} theta^T m - A(theta)`` with
   ``m = alpha D + (1 - alpha) grad A(theta_k)`` (exact projection per family);
5. remember the ``theta_k`` with the lowest ``rho``-quantile (``select=
   "quantile"``, the paper's rule; see
   :data:`~avrisk.rare.cross_entropy_search.SELECTION_RULES` for another).

The estimate comes from ``n`` fresh samples of the remembered proposal:
``p_hat = mean(w_i 1{f_i <= gamma})``, unbiased for ``P0(f <= gamma)``.

:class:`CrossEntropy` is the method behind the engine's estimator protocol
(:mod:`avrisk.rare.estimator`): its ``init`` / ``step`` pair carries everything
the next iteration needs in a
:class:`~avrisk.rare.cross_entropy_search.CEState` and diagnostics in a
:class:`CEInfo`, so a driver can checkpoint between iterations. It is
registered as ``"ce"`` and, with a defensive final stage of 10% by default, as
``"defensive"``. :func:`cross_entropy` is the top-level function. The steps it
shares with mixture CE (:mod:`avrisk.rare.mixture`) are in
:mod:`avrisk.rare.cross_entropy_search`; the settings of both are here.

References
----------
M. O'Kelly, A. Sinha, H. Namkoong, J. Duchi, R. Tedrake. "Scalable end-to-end
autonomous vehicle testing via rare-event simulation." NeurIPS 2018.
R. Y. Rubinstein, D. P. Kroese. The Cross-Entropy Method. Springer, 2004.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from avrisk.rare.black_box import estimate
from avrisk.rare.cross_entropy_search import (
    SELECTION_RULES,
    CEState,
    search_budget,
    search_checkpoint,
    search_convergence,
    search_diagnostics,
    search_final_estimate,
    search_level,
    search_stage_label,
    search_structure,
)
from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    DiagnosticTable,
    EstimatorSettings,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.problem import (
    BatchFunction,
    RareEventProblem,
)
from avrisk.rare.proposal_audit import audit_bound, audit_doubts
from avrisk.rare.results import CEInfo, Estimate

#: The types of the settings that the variants of :class:`CESettings` give
#: other defaults (:class:`~avrisk.rare.mixture.MixtureSettings`): their
#: constraints, declared once.
EliteLevel = Annotated[
    float, Field(gt=0.0, lt=1.0, description="Elite quantile level.")
]
SearchIterations = Annotated[int, Field(ge=0, description="Search iterations.")]
ShareOfP0 = Annotated[float, Field(ge=0.0, lt=1.0)]
AuditParticles = Annotated[
    int | None,
    Field(
        ge=0,
        description="Particles per level of the audit's subset simulation "
        "(None: by n_final; 0: no audit).",
    ),
]
#: Final draws per particle of the default audit, and its fewest and most
#: particles per level (:meth:`CESettings.audit`).
AUDIT_DRAWS_PER_PARTICLE = 50
AUDIT_PARTICLES = (20, 1000)


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
        (:data:`~avrisk.rare.cross_entropy_search.SELECTION_RULES`);
        ``"quantile"`` is the paper's.
    defensive : float, default=0.0
        Fraction ``lam`` in [0, 1) of the final stage drawn from the base
        instead of the chosen proposal (a defensive mixture,
        :mod:`avrisk.rare.defensive`): every weight is then at most
        ``1 / lam``, so a proposal that misses part of the event, or has
        heavy-tailed weights, cannot make the estimate or its standard error
        collapse. 0 (the paper's): the proposal alone.
    space : {"natural", "standard"}, default="natural"
        Where the proposals live
        (:func:`~avrisk.rare.cross_entropy_search.search_structure`): the
        base's own family at other parameters (the paper's), or mean shifts of
        the base's standard normals
        (:class:`~avrisk.rare.families.StandardSpaceShift`), whose weights have
        finite variance however far the search goes.
    audit_particles : int or None, default=None
        Particles per level of the independent subset simulation that checks,
        after the final stage, that its proposal draws where the event is
        (:mod:`avrisk.rare.proposal_audit`): a failure region the search
        missed makes the run say caution. Its calls (at most
        :func:`~avrisk.rare.proposal_audit.audit_bound`, 12 per particle;
        typically half that) count in the run's. None: one per
        ``AUDIT_DRAWS_PER_PARTICLE`` final draws, between ``AUDIT_PARTICLES``'s
        bounds (:meth:`audit`); 0: no audit.
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
    audit_particles: AuditParticles = None

    @field_validator("audit_particles")
    @classmethod
    def _audit_replicates_fill(cls, particles: int | None) -> int | None:
        low = AUDIT_PARTICLES[0]
        if particles is not None and 0 < particles < low:
            raise ValueError(f"must be 0 (no audit) or at least {low}")
        return particles

    def audit(self) -> int:
        """Particles per level of the audit: ``audit_particles``, or the default's.

        One per ``AUDIT_DRAWS_PER_PARTICLE`` final draws, within
        ``AUDIT_PARTICLES`` (a subset simulation needs 10 per replicate; a
        thousand find the regions that hold much of ``p``), so the audit costs
        about a tenth of the final stage's calls.
        """
        if self.audit_particles is not None:
            return self.audit_particles
        low, high = AUDIT_PARTICLES
        return min(max(self.n_final // AUDIT_DRAWS_PER_PARTICLE, low), high)


class DefensiveCESettings(CESettings):
    """CE with a defensive final stage: ``defensive`` must be above 0."""

    OMIT_IF_DEFAULT = ()

    defensive: float = Field(
        0.1,
        gt=0.0,
        lt=1.0,
        description="Share of the final stage drawn from P0 (weights <= 1/share).",
    )


@register_estimator
class CrossEntropy:
    """Cross-entropy importance sampling (module docstring) as an Estimator."""

    name = "ce"
    label = "cross-entropy"
    Settings: type[CESettings] = CESettings
    weighted = True
    decomposable = True
    budget_is_bound = True  # the audit's levels may reach gamma early
    searches = True

    def __init__(self, settings: CESettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """Search iterations times their samples, the final stage, the audit's bound."""
        return search_budget(self.settings)

    def budget_not_redrawn(self) -> int:
        """The audit's: its points are drawn in standard space and moved."""
        return audit_bound(self.settings.audit())

    def describe(self) -> str:
        """``"CE 20x5,000 + 100,000, audit 1,000"`` (and the defensive share)."""
        s = self.settings
        text = f"CE {s.n_iter}x{s.n_per_iter:,} + {s.n_final:,}"
        text += f", defensive {s.defensive:g}" if s.defensive else ""
        return text + (f", audit {s.audit():,}" if s.audit() else "")

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
            "cross_entropy",
            state,
            sampled,
            s.n_final,
            problem,
            context,
            s.audit(),
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
        return search_stage_label(estimate, stage, "CE iteration")

    #: Whether the search reached a threshold and held it.
    convergence = staticmethod(search_convergence)
    #: A failure region the final stage hardly draws, found by the audit.
    doubts = staticmethod(audit_doubts)


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
