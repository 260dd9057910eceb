"""Mixture cross-entropy importance sampling: one proposal for several failure regions.

A cross-entropy proposal (:mod:`avrisk.rare.cross_entropy`) is one member of
the base family: it sits on one failure region. Where the event has several
separate modes, its samples miss all but one, and the estimate comes out low
with an interval that is too narrow. Here the proposal is the mixture

    q = lam P0 + (1 - lam) sum_k pi_k q_k

of ``K`` members ``q_k`` of the base family (each a copy of the base's
structure, its own parameter in the base's search box) and of the base itself
with weight ``lam`` (:class:`~avrisk.rare.mixture_em.MixtureProposal`: every
weight is ``p0 / q <= 1 / lam``). It is searched as cross-entropy searches one
member (improved cross-entropy with mixtures: Kurtz & Song 2013; Geyer,
Papaioannou & Straub 2019). For iteration ``k = 0 .. n_iter - 1``, with ``q``
the base at ``k = 0``:

1. draw ``N`` samples of ``q`` and evaluate ``f``;
2. the level ``gamma_k = max(gamma, rho-quantile of f)`` and its elite
   ``f <= gamma_k``, weighted by ``w = p0 / q`` self-normalised in log space
   (:func:`~avrisk.rare.cross_entropy_search.search_level`, shared with CE);
3. fit the components to the weighted elite by EM
   (:func:`~avrisk.rare.mixture_em.fit_mixture`: responsibilities from the
   sufficient statistics, each component's weighted mean statistic projected
   by the family's CE projection, components left with less than
   ``min_weight`` of the elite weight removed);
4. smooth each component as CE does: ``project(alpha m_k + (1 - alpha) grad
   A(theta_k))`` with ``theta_k`` the component it grew from (the base at
   ``k = 0``), and merge the components that overlap
   (:func:`~avrisk.rare.mixture_em.merge_overlapping`);
5. remember the sampled mixture with the best selection score
   (:data:`~avrisk.rare.cross_entropy_search.SELECTION_RULES`, as CE).

The estimate comes from ``n_final`` fresh samples of the remembered mixture,
``mean(w 1{f <= g})`` per threshold, with ESS and Pareto ``k`` per threshold.

At the first iteration EM starts from the elite (of the base) split into
groups around weighted k-means++ centres
(:func:`~avrisk.rare.mixture_em.seed_components`), so distant groups of
elites, the candidate modes, get a component each; later iterations start EM
from the components that sampled them, so each component follows its mode
down the levels. So ``K`` starts at ``n_components`` (fewer for fewer
distinct elites) and can only fall: a mode that has no elite at the first
level is not found later (as with CE), and only the defensive share of
``P0`` samples it. :mod:`avrisk.rare.mixture_em` says how the mixture is
seeded, fitted and merged, and why.

:class:`MixtureCrossEntropy` is the method behind the estimator protocol
(:mod:`avrisk.rare.estimator`), registered as ``"mixture"``;
:func:`mixture_ce` is the top-level function.

References
----------
N. Kurtz, J. Song. "Cross-entropy-based adaptive importance sampling using
Gaussian mixture." Structural Safety 42, 2013.
S. Geyer, I. Papaioannou, D. Straub. "Cross entropy-based importance sampling
using Gaussian densities revisited." Structural Safety 76, 2019.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import Field

from avrisk.rare.black_box import estimate
from avrisk.rare.cross_entropy import (
    CESettings,
    EliteLevel,
    SearchIterations,
    ShareOfP0,
)
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
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    DiagnosticTable,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.mixture_em import (
    MixtureProposal,
    fit_mixture,
    merge_overlapping,
    seed_components,
)
from avrisk.rare.problem import (
    BatchFunction,
    RareEventProblem,
)
from avrisk.rare.proposal_audit import audit_bound, audit_doubts
from avrisk.rare.results import Estimate, MixtureInfo

#: Extra key of the seeding generator, so that it draws no chunk's stream.
SEEDING_STREAM = 0x6D6978


class MixtureSettings(CESettings):
    """Settings of mixture cross-entropy importance sampling.

    Those of :class:`~avrisk.rare.cross_entropy.CESettings`, with other
    defaults for ``rho`` (EM needs elites for every component, hence more
    than CE's 0.01), ``n_iter`` and ``defensive``, and two of its own.

    Attributes
    ----------
    n_components : int, default=4
        Components at the first iteration; they may die or merge later.
    rho : float, default=0.1
        Quantile level of the elite, in (0, 1).
    n_iter : int, default=20
        Search iterations (0: the final stage samples the base).
    defensive : float, default=0.1
        Weight ``lam`` of the base in every mixture, in [0, 1): every weight
        is at most ``1 / lam``.
    min_weight : float, default=0.02
        Share of the elite weight below which a component dies.
    """

    OMIT_IF_DEFAULT = ("space",)

    n_components: int = Field(
        4, ge=1, description="Components K at the start (they may die or merge)."
    )
    rho: EliteLevel = 0.1
    n_iter: SearchIterations = 20
    defensive: ShareOfP0 = Field(
        0.1, description="Weight of P0 in every mixture (weights <= 1/defensive)."
    )
    min_weight: float = Field(
        0.02,
        gt=0.0,
        lt=1.0,
        description="Share of the elite weight below which a component dies.",
    )

    def recorded(self) -> dict[str, Any]:
        """As CE's, ``n_components`` first (as runs have always recorded it)."""
        out = super().recorded()
        return {"n_components": out.pop("n_components"), **out}


@register_estimator
class MixtureCrossEntropy:
    """Mixture cross-entropy importance sampling (module docstring) as an Estimator."""

    name = "mixture"
    label = "cross-entropy, mixture"
    Settings: type[MixtureSettings] = MixtureSettings
    weighted = True
    decomposable = True
    budget_is_bound = True  # the audit's levels may reach gamma early
    searches = True

    def __init__(self, settings: MixtureSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """Search iterations times their samples, the final stage, the audit's bound."""
        return search_budget(self.settings)

    def budget_not_redrawn(self) -> int:
        """The audit's: its points are drawn in standard space and moved."""
        return audit_bound(self.settings.audit())

    def describe(self) -> str:
        """``"mixture CE (4 components) 20x5,000 + 100,000, defensive 0.1"``.

        Then the audit's particles per level, where there is one: ``", audit
        1,000"``.
        """
        s = self.settings
        text = (
            f"mixture CE ({s.n_components} components) {s.n_iter}x{s.n_per_iter:,} "
            f"+ {s.n_final:,}, defensive {s.defensive:g}"
        )
        return text + (f", audit {s.audit():,}" if s.audit() else "")

    def init(self, problem: RareEventProblem) -> CEState:
        """Before the first iteration: the proposal is the base distribution."""
        base = problem.base
        structure = search_structure(base, self.settings.space)
        start = MixtureProposal([structure], [1.0], base, self.settings.defensive)
        return CEState(start, 0, start, (math.inf,), -1, 0)

    def done(self, state: CEState) -> bool:
        """After ``n_iter`` iterations."""
        return state.iteration >= self.settings.n_iter

    def step(
        self, state: CEState, problem: RareEventProblem, context: EstimationContext
    ) -> tuple[CEState, MixtureInfo]:
        """One iteration (steps 1-5 of the module docstring).

        The samples of iteration ``k`` come from stage ``k + 1`` and the
        seeding of the first iteration from a generator of the run seed and
        that stage, so an iteration re-run from a checkpointed state gives the
        same result.
        """
        s = self.settings
        stage = state.iteration + 1
        sampled = state.proposal
        result = context.stage(problem, sampled, s.n_per_iter, stage, keep_stats=True)
        assert result.stats is not None
        level = search_level(result, s.rho, problem.gamma, state.iteration)
        positive = level.elite_weights > 0
        stats = result.stats[level.elite][positive]
        elite_weights = level.elite_weights[positive]
        if state.iteration == 0:
            seeding = np.random.SeedSequence(
                [context.seed, stage], spawn_key=(SEEDING_STREAM,)
            )
            (structure,) = sampled.components  # init's one component, at P0
            start = seed_components(
                structure,
                stats,
                elite_weights,
                s.n_components,
                np.random.default_rng(seeding),
            )
            grew_from = [structure] * len(start[0])
        else:
            start = sampled.components, sampled.weights
            grew_from = list(sampled.components)
        fit = fit_mixture(*start, stats, elite_weights, s.min_weight)
        smoothed = [
            grew_from[k].project(
                s.alpha * m + (1.0 - s.alpha) * grew_from[k].mean_param()
            )
            for k, m in zip(fit.origin, fit.targets, strict=True)
        ]
        components, weights = merge_overlapping(smoothed, fit.weights)
        n_evals = state.n_evals + s.n_per_iter
        info = MixtureInfo(
            iteration=state.iteration,
            gamma_k=level.gamma_k,
            quantile=level.quantile,
            ess=level.elite_ess,
            n_elite=int(level.elite.sum()),
            n_hits=level.n_hits,
            n_evals=n_evals,
            rel_var=level.rel_var,
            n_components=len(components),
            weights=tuple(float(w) for w in weights),
        )
        score = SELECTION_RULES[s.select](level)
        better = score < state.best_score
        new_state = CEState(
            proposal=MixtureProposal(components, weights, problem.base, s.defensive),
            iteration=stage,
            best=sampled if better else state.best,
            best_score=score if better else state.best_score,
            best_iteration=state.iteration if better else state.best_iteration,
            n_evals=n_evals,
        )
        return new_state, info

    def finalize(
        self, state: CEState, problem: RareEventProblem, context: EstimationContext
    ) -> Estimate:
        """Fresh samples of the best mixture."""
        s = self.settings
        return search_final_estimate(
            "mixture_ce",
            state,
            state.best,
            s.n_final,
            problem,
            context,
            s.audit(),
        )

    def progress(self, info: MixtureInfo) -> str:
        """``"iter 3: gamma_k=0.21 hits=12 ESS=40 components=4"``."""
        return (
            f"iter {info.iteration}: gamma_k={info.gamma_k:.3g} "
            f"hits={info.n_hits} ESS={info.ess:.0f} components={info.n_components}"
        )

    def checkpoint(
        self, state: CEState, infos: Sequence[MixtureInfo]
    ) -> dict[str, Any]:
        """The mixtures (components and weights) and the iterations so far."""
        return search_checkpoint(state, infos)

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """The search: levels, quantiles, hits, ESS and live components."""
        return search_diagnostics(
            "Mixture cross-entropy search",
            estimate,
            extra=(("live components", "n_components"),),
        )

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """``"iteration 3"`` (stage 4), or ``"the final stage"``."""
        return search_stage_label(estimate, stage)

    #: Whether the search reached a threshold and held it.
    convergence = staticmethod(search_convergence)
    #: A failure region the final stage hardly draws, found by the audit.
    doubts = staticmethod(audit_doubts)


def mixture_ce(
    f: BatchFunction, base: ExponentialFamily, gamma: float, **options: Any
) -> Estimate:
    """Mixture cross-entropy: ``estimate("mixture", f, base, gamma, **options)``."""
    return estimate("mixture", f, base, gamma, **options)
