"""Naive Monte Carlo: the baseline every rare-event estimator is compared with.

    X_1..X_n ~ P0 i.i.d.;  p_hat = #{f(X_i) <= gamma} / n

It needs about ``1 / (p eps^2)`` calls of ``f`` for relative accuracy ``eps``.
The interval is exact binomial (Clopper-Pearson) by default, so zero hits give
``p = 0`` with an honest upper bound (about ``3.7 / n`` at 95%), never a
zero-width interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, NamedTuple

from pydantic import Field

from avrisk.rare.black_box import estimate
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    DiagnosticTable,
    EstimatorSettings,
    no_doubts,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.final_stage import binomial_estimates, bracket_failures
from avrisk.rare.problem import (
    FINAL_STAGE,
    BatchFunction,
    RareEventProblem,
)
from avrisk.rare.results import Estimate, SearchConvergence


class NaiveSettings(EstimatorSettings):
    """Settings of naive Monte Carlo."""

    OMIT_IF_DEFAULT = ("interval",)

    n_final: int = Field(100_000, ge=1, description="Samples (= calls of f).")
    interval: Literal["clopper-pearson", "wilson"] = Field(
        "clopper-pearson", description="Binomial confidence interval (95%)."
    )


class NaiveState(NamedTuple):
    """Naive Monte Carlo has no steps: its one stage is the final one."""


@register_estimator
class NaiveMC:
    """Naive Monte Carlo as an :class:`~avrisk.rare.estimator.Estimator`."""

    name = "naive"
    label = "naive Monte Carlo"
    Settings = NaiveSettings
    weighted = False
    decomposable = True
    budget_is_bound = False
    searches = False  # every draw is of P0: no region can be left out

    def __init__(self, settings: NaiveSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """``n_final`` calls of ``f``."""
        return self.settings.n_final

    def budget_not_redrawn(self) -> int:
        """0: every sample is a fresh draw of its stage's proposal."""
        return 0

    def describe(self) -> str:
        """``"naive MC, 100,000 rollouts"``."""
        return f"naive MC, {self.settings.n_final:,} rollouts"

    def init(self, problem: RareEventProblem) -> NaiveState:
        """Nothing to prepare."""
        return NaiveState()

    def done(self, state: NaiveState) -> bool:
        """Always: there is no search."""
        return True

    def step(self, state: NaiveState, problem: Any, context: Any) -> Any:
        """Never called (:meth:`done` is always true)."""
        raise RuntimeError("naive Monte Carlo has no search steps")

    def finalize(
        self, state: NaiveState, problem: RareEventProblem, context: EstimationContext
    ) -> Estimate:
        """Sample ``P0``, count the hits of every threshold."""
        n, interval = self.settings.n_final, self.settings.interval
        stage = context.stage(problem, problem.base, n, FINAL_STAGE, final_after=0)
        by_gamma = bracket_failures(
            lambda v: binomial_estimates(v, problem.thresholds, interval),
            stage.values,
            stage.failed,
        )
        return Estimate(
            method="naive_mc",
            gamma=problem.gamma,
            by_gamma=by_gamma,
            n_evals=stage.values.size,
            stopped_by=stage.stopped_by or "budget",
        )

    def progress(self, info: Any) -> str:
        """Nothing to say between steps."""
        return ""

    def checkpoint(self, state: NaiveState, infos: Sequence[Any]) -> dict[str, Any]:
        """No state worth recording."""
        return {}

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """No per-step tables."""
        return []

    @staticmethod
    def convergence(estimate: dict[str, Any], gamma: float) -> SearchConvergence | None:
        """None: nothing is searched."""
        return None

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """``"the draws of P0"``: its one stage."""
        return "the draws of P0"

    doubts = staticmethod(no_doubts)


def naive_mc(
    f: BatchFunction, base: ExponentialFamily, gamma: float, n: int, **options: Any
) -> Estimate:
    """Naive MC of ``n`` samples: ``estimate("naive", f, base, gamma, n_final=n, ...)``.

    The keywords: :func:`~avrisk.rare.black_box.estimate`.

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import FixedCovNormal, naive_mc
    >>> base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    >>> est = naive_mc(lambda x: x[:, 0], base, gamma=-2.0, n=20_000, seed=1)
    >>> bool(abs(est.p - 0.02275) < 4 * est.stderr)
    True
    """
    return estimate("naive", f, base, gamma, n_final=n, **options)
