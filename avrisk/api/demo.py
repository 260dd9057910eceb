"""The demo's two parts, as ``avrisk demo`` runs them.

1. The estimation engine against problems with exact answers
   (:mod:`avrisk.testing`): at an equal budget of calls of ``f``, how far
   naive Monte Carlo and the cross-entropy method land from the exact
   probability.
2. The bundled default scenario: ``splitting_is`` and naive Monte Carlo at
   the same budget of rollouts, and a larger naive reference
   (:func:`avrisk.api.runs.compare_runs`: the paper's Table 1 and Fig. 2-3).

:func:`run_demo` prints nothing: the cross-entropy runs and the scenario's
runs report to ``progress`` as :mod:`avrisk.api.events`, and the first
part's :class:`ExactEstimates` is handed to ``progress`` too as soon as it is
done (the second part takes minutes).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from avrisk.api.errors import UserError
from avrisk.api.events import Event, run_events
from avrisk.rare import CrossEntropy, Estimate, cross_entropy, naive_mc
from avrisk.rare.cross_entropy import CESettings
from avrisk.testing import AnalyticProblem, beta_sum_problem, gaussian_linear_problem

if TYPE_CHECKING:
    from avrisk.api.result import EstimationResult
    from avrisk.pipeline import RunSettings

__all__ = ["MIN_BUDGET", "DemoResult", "ExactEstimates", "run_demo"]

#: Fewest calls of ``f`` per estimator: with fewer, the 100-dimensional
#: search has too few elite samples per iteration.
MIN_BUDGET = 50_000
#: The scenario of the second part.
DEMO_SCENARIO = "highway_default"


@dataclass(frozen=True)
class ExactEstimates:
    """The first part: each problem's estimates at an equal budget.

    Attributes
    ----------
    budget : int
        Calls of ``f`` per estimator.
    seed : int
        The estimators' seed.
    problems : tuple of (AnalyticProblem, tuple of Estimate)
        Each problem (its exact ``p``: ``p_exact``) with its naive Monte
        Carlo and cross-entropy estimates, in that order.
    written : pathlib.Path or None
        The JSON file of the estimates, when one was asked for.
    """

    budget: int
    seed: int
    problems: tuple[tuple[AnalyticProblem, tuple[Estimate, ...]], ...]
    written: Path | None


@dataclass(frozen=True)
class DemoResult:
    """Both parts: the exact problems' estimates, the scenario's comparison.

    ``scenario`` is None when the second part was skipped (``rollouts=0``).
    """

    exact: ExactEstimates
    scenario: EstimationResult | None


#: What :func:`run_demo` tells its ``progress``: the runs' events, and the
#: first part's estimates once it is done.
DemoProgress = Callable[[Event | ExactEstimates], None]


def run_demo(
    *,
    budget: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    scenario_out: str | Path = "runs/demo",
    rollouts: int = 20_000,
    reference: int = 50_000,
    progress: DemoProgress | None = None,
) -> DemoResult:
    """Run both parts of the demo.

    Parameters
    ----------
    budget : int, default=100_000
        Calls of ``f`` per estimator on the exact problems (at least
        :data:`MIN_BUDGET`): the sum of six longitudinal offsets
        ``80 + 40 Beta(2, 2)`` m below a threshold (``p = 1e-5``), and a
        linear limit state of a 100-dimensional standard normal (``p = 1e-6``).
    seed : int, default=0
        Seeds every estimator and run.
    out : str or Path, optional
        Write the exact problems' estimates here as JSON.
    scenario_out : str or Path, default="runs/demo"
        The run directories and report of the second part (resumed).
    rollouts : int, default=20_000
        Rollouts of ``splitting_is`` on the scenario, and of naive Monte
        Carlo (0: skip the second part).
    reference : int, default=50_000
        Rollouts of the naive reference run (0: none; the ratios then use
        ``splitting_is``'s own estimate of ``p``).
    progress : callable, optional
        Called with every event of the runs (:mod:`avrisk.api.events`) and
        with the :class:`ExactEstimates` before the second part starts.

    Raises
    ------
    UserError
        For a budget or scenario settings that cannot be used, and what
        :func:`avrisk.api.runs.compare_runs` raises.
    """
    tell = progress if progress is not None else _ignore
    if budget < MIN_BUDGET:
        raise UserError(f"the demo's budget is at least {MIN_BUDGET:,} calls of f")
    method = _scenario_settings(rollouts, seed) if rollouts else None
    written = None if out is None else Path(out)
    exact = ExactEstimates(budget, seed, _exact_problems(budget, seed, tell), written)
    if written is not None:
        written.write_text(json.dumps(_document(exact), indent=2))
    tell(exact)
    if method is None:
        return DemoResult(exact, None)
    # the simulator (torch) is loaded here, not with this module
    from avrisk.api.runs import compare_runs

    scenario = compare_runs(
        DEMO_SCENARIO,
        Path(scenario_out),
        method,
        reference_n=reference,
        failures=3,
        device="cpu",
        progress=tell,
    )
    return DemoResult(exact, scenario)


def _ignore(event: Event | ExactEstimates) -> None:
    """The progress callback that ignores every event."""


def _exact_problems(
    budget: int, seed: int, progress: DemoProgress
) -> tuple[tuple[AnalyticProblem, tuple[Estimate, ...]], ...]:
    """Naive MC and CE on each exact problem, ``budget`` calls of ``f`` each.

    CE takes 8 iterations of ``budget / 25`` samples (at least 100) and its
    final stage the rest, with no audit (:mod:`avrisk.rare.proposal_audit`,
    :mod:`avrisk.rare.directional_audit`): the part compares precision at
    equal calls, and each problem has one failure region.
    """
    problems = [beta_sum_problem(6, p=1e-5), gaussian_linear_problem(100, p=1e-6)]
    n_iter, n_per_iter = 8, max(100, budget // 25)
    settings = CESettings(
        rho=0.1,
        n_per_iter=n_per_iter,
        n_iter=n_iter,
        n_final=budget - n_iter * n_per_iter,
        audit_particles=0,
    )
    rows = []
    for problem in problems:
        naive = naive_mc(problem.f, problem.base, problem.gamma, budget, seed=seed)
        ce = _cross_entropy(problem, settings, seed, progress)
        rows.append((problem, (naive, ce)))
    return tuple(rows)


def _cross_entropy(
    problem: AnalyticProblem, settings: CESettings, seed: int, progress: DemoProgress
) -> Estimate:
    """CE on an exact problem, its calls of ``f`` reported as a run's events."""
    method = CrossEntropy(settings)
    with run_events(f"CE {problem.name}", None, progress) as monitor:
        monitor.start(method.budget(), method.describe())
        return cross_entropy(
            problem.f,
            problem.base,
            problem.gamma,
            settings=settings,
            seed=seed,
            callback=lambda info, state: monitor.status(method.progress(info)),
            on_batch=lambda batch: monitor.advance(len(batch.ids), replayed=False),
            directional_audit=False,
        )


def _document(exact: ExactEstimates) -> dict[str, dict[str, object]]:
    """The JSON of the first part: each problem's exact ``p`` and estimates."""
    return {
        problem.name: {
            "p_exact": problem.p_exact,
            "naive_mc": naive.to_dict(),
            "cross_entropy": ce.to_dict(),
        }
        for problem, (naive, ce) in exact.problems
    }


def _scenario_settings(rollouts: int, seed: int) -> RunSettings:
    """``splitting_is`` on the scenario: ``rollouts // 10`` particles a level.

    About half the budget goes to levels and moves at ``gamma`` on
    ``highway_default`` and the final stage takes the other half: the
    coverage benchmark's preset (BENCHMARKS.md, "Coverage"), whose intervals
    cover the large naive reference there. CE on the same budget is about as
    precise in most seeds but far off, with too narrow an interval, in some.
    """
    from avrisk.api.runs import settings

    return settings(
        "splitting_is",
        gamma=0.1,
        gamma_test=(0.2, 0.3, 0.5, 1.0),
        n_particles=rollouts // 10,
        n_final=rollouts // 2,
        seed=seed,
        batch_size=1024,
    )
