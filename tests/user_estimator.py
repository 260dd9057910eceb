"""A user's own estimator, in one module: importing it registers ``plain_mc``.

Plain Monte Carlo with a normal (Wald) 95% interval, written against the
estimator protocol (:mod:`avrisk.rare.estimator`) alone: settings, a state,
the protocol's methods and one registration. Its one stage draws ``n_final``
samples of ``P0`` through the context, as every estimator's stages do, so the
engine and a scenario run (``avrisk.estimate(..., method="plain_mc")``) take
it as they take the bundled ones.
"""

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from pydantic import Field

from avrisk.rare.estimator import EstimatorSettings, no_doubts, register_estimator
from avrisk.rare.problem import FINAL_STAGE
from avrisk.rare.results import Estimate, GammaEstimate

#: The standard normal's 97.5% quantile: a two-sided 95% interval.
Z95 = 1.959963984540054


class PlainSettings(EstimatorSettings):
    """Settings of plain Monte Carlo."""

    n_final: int = Field(10_000, ge=1, description="Samples of P0 (= calls of f).")


class PlainState(NamedTuple):
    """No search: the one stage is the final one."""


def wald(hits: int, n: int, gamma: float, n_failed: int) -> GammaEstimate:
    """``p = hits / n`` with its normal 95% interval; failed samples bracketed."""
    p, p_high = hits / n, (hits + n_failed) / n
    stderr = float(np.sqrt(p * (1 - p) / n))
    stderr_high = float(np.sqrt(p_high * (1 - p_high) / n))
    return GammaEstimate(
        gamma=gamma,
        p=p,
        stderr=stderr,
        ci=(max(0.0, p - Z95 * stderr), min(1.0, p_high + Z95 * stderr_high)),
        n_hits=hits,
        ess=float(hits),
        n_samples=n,
        n_failed=n_failed,
        p_if_failed_dangerous=p_high,
        interval="Wald",
    )


@register_estimator
class PlainMonteCarlo:
    """Plain Monte Carlo as an :class:`~avrisk.rare.estimator.Estimator`."""

    name = "plain_mc"
    label = "plain Monte Carlo (Wald interval)"
    Settings = PlainSettings
    weighted = False
    decomposable = True
    budget_is_bound = False
    searches = False  # every sample is a draw of P0

    def __init__(self, settings: PlainSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        return self.settings.n_final

    def budget_not_redrawn(self) -> int:
        return 0

    def describe(self) -> str:
        return f"plain MC, {self.settings.n_final:,} samples"

    def init(self, problem: Any) -> PlainState:
        return PlainState()

    def done(self, state: PlainState) -> bool:
        return True

    def step(self, state: PlainState, problem: Any, context: Any) -> Any:
        raise RuntimeError("plain Monte Carlo has no search steps")

    def finalize(self, state: PlainState, problem: Any, context: Any) -> Estimate:
        """Draw ``n_final`` samples of ``P0``; count the hits of every threshold."""
        n = self.settings.n_final
        stage = context.stage(problem, problem.base, n, FINAL_STAGE, final_after=0)
        failed = (
            np.zeros(stage.values.size, bool) if stage.failed is None else stage.failed
        )
        by_gamma = {
            g: wald(
                int(np.count_nonzero((stage.values <= g) & ~failed)),
                stage.values.size,
                g,
                int(failed.sum()),
            )
            for g in problem.thresholds
        }
        return Estimate(
            method=self.name,
            gamma=problem.gamma,
            by_gamma=by_gamma,
            n_evals=stage.values.size,
            stopped_by=stage.stopped_by or "budget",
        )

    def progress(self, info: Any) -> str:
        return ""

    def checkpoint(self, state: PlainState, infos: Sequence[Any]) -> dict[str, Any]:
        return {}

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[Any]:
        return []

    @staticmethod
    def convergence(estimate: dict[str, Any], gamma: float) -> None:
        return None

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        return "the draws of P0"

    doubts = staticmethod(no_doubts)
