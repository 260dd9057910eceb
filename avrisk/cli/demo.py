"""``avrisk demo``: the main job of the README, in a few minutes.

1. The estimation engine against problems with exact answers: at an equal
   budget of calls of ``f``, how far naive Monte Carlo and the cross-entropy
   method land from the exact probability.
2. The bundled default scenario: importance sampling from subset
   simulation's particles (``splitting_is``, the estimator whose intervals
   cover the large reference there) and naive Monte Carlo at the same budget
   of rollouts, and a larger naive reference (``avrisk compare``: the paper's
   Table 1 and Fig. 2-3), with the run directories and the HTML report under
   ``--scenario-out``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from avrisk.cli.common import (
    check_output_file,
    check_output_folder,
    err_console,
    out_console,
    user_errors,
)
from avrisk.cli.progress import RichProgress, RichRunMonitor
from avrisk.cli.tables import add_columns, compact_table
from avrisk.rare import CrossEntropy, Estimate, cross_entropy, naive_mc
from avrisk.rare.cross_entropy import CESettings
from avrisk.testing import AnalyticProblem, beta_sum_problem, gaussian_linear_problem

METHOD_LABELS = {"naive_mc": "naive MC", "cross_entropy": "CE"}


def analytic_table(
    budget: int, seed: int, results: list[tuple[AnalyticProblem, list[Estimate]]]
) -> Table:
    """Each problem's estimates against its exact ``p``; fits 80 columns.

    One section per problem: a row with its name and exact ``p``, then a
    row per method.
    """
    table = compact_table(f"Equal budget: {budget:,} calls of f each (seed {seed})")
    add_columns(
        table,
        ["problem", "method", "estimate", "95% CI", "error", "hits"],
        text=["problem", "method"],
    )
    for problem, estimates in results:
        table.add_row(problem.name, "exact", f"{problem.p_exact:.3e}")
        for est in estimates:
            lo, hi = est.ci
            rel = (est.p - problem.p_exact) / problem.p_exact
            table.add_row(
                "",
                METHOD_LABELS[est.method],
                f"{est.p:.3e}",
                f"{lo:.2e}..{hi:.2e}",
                f"{rel:+.1%}",
                str(est.n_hits),
            )
        table.add_section()
    return table


def demo(
    budget: int = typer.Option(
        100_000,
        min=50_000,
        help="Calls of f per estimator (at least 50,000: with fewer, the "
        "100-dimensional search has too few elite samples per iteration).",
    ),
    seed: int = typer.Option(0, min=0, help="Run seed."),
    out: Path | None = typer.Option(None, help="Write both estimates as JSON here."),
    scenario_out: Path = typer.Option(
        Path("runs/demo"), help="Run directories and report of the scenario part."
    ),
    rollouts: int = typer.Option(
        20_000,
        min=0,
        help="Rollouts per method on the default scenario (0: skip).",
    ),
    reference: int = typer.Option(
        50_000,
        min=0,
        help="Rollouts of the naive reference run on the default scenario "
        "(0: none; the ratios then use splitting_is's own estimate of p).",
    ),
) -> None:
    """The main job: cross-entropy vs naive MC on exact problems, then a scenario.

    First two problems with known answers at an equal budget of calls: the sum
    of six longitudinal offsets 80 + 40 Beta(2,2) m (the paper's marginal)
    below a threshold (p = 1e-5), and a linear limit state of a
    100-dimensional standard normal (p = 1e-6). Then `avrisk compare` on the
    bundled highway_default scenario (the lidar imitation ego in learned
    traffic), with its report under --scenario-out.
    """
    with user_errors():
        if out is not None:
            check_output_file(out)
        if rollouts:
            check_output_folder(scenario_out, "--scenario-out")
    console = out_console
    problems = [beta_sum_problem(6, p=1e-5), gaussian_linear_problem(100, p=1e-6)]
    n_iter, n_per_iter = 8, max(100, budget // 25)
    n_final = budget - n_iter * n_per_iter
    results, rows = {}, []
    for problem in problems:
        naive = naive_mc(problem.f, problem.base, problem.gamma, budget, seed=seed)
        ce = _cross_entropy(console, problem, n_iter, n_per_iter, n_final, seed)
        rows.append((problem, [naive, ce]))
        results[problem.name] = {
            "p_exact": problem.p_exact,
            "naive_mc": naive.to_dict(),
            "cross_entropy": ce.to_dict(),
        }
    console.print(analytic_table(budget, seed, rows))
    console.print(
        "Naive Monte Carlo needs about 1/(p eps^2) calls for relative error eps; "
        "cross-entropy importance sampling reaches a few percent with the same budget."
    )
    if out is not None:
        out.write_text(json.dumps(results, indent=2))
        console.print(f"wrote {out}")
    if rollouts:
        _scenario_part(console, scenario_out, rollouts, reference, seed)


def _cross_entropy(
    console: Console,
    problem: AnalyticProblem,
    n_iter: int,
    n_per_iter: int,
    n_final: int,
    seed: int,
) -> Estimate:
    """CE on an analytic problem, with a progress bar over its calls of f."""
    ce_settings = CESettings(
        rho=0.1, n_per_iter=n_per_iter, n_iter=n_iter, n_final=n_final
    )
    method = CrossEntropy(ce_settings)
    with RichRunMonitor(console, f"CE {problem.name}") as monitor:
        monitor.start(method.budget(), method.describe())
        return cross_entropy(
            problem.f,
            problem.base,
            problem.gamma,
            settings=ce_settings,
            seed=seed,
            callback=lambda info, state: monitor.status(method.progress(info)),
            on_batch=lambda batch: monitor.advance(len(batch.ids), replayed=False),
        )


def _scenario_part(
    console: Console, out: Path, rollouts: int, reference: int, seed: int
) -> None:
    """splitting_is and naive MC on the bundled scenario, and a naive reference.

    ``rollouts // 10`` particles per level (about half the budget in levels and
    moves at gamma on ``highway_default``) and a final stage of half the
    budget: the coverage benchmark's preset, about 120 times naive sampling's
    precision at 0.1 s over 20 seeds, its intervals covering the 4.5-million-rollout
    reference in 20 of 20 (BENCHMARKS.md, "Coverage"). CE on the same budget is
    about as precise in most seeds but far off, with too narrow an interval, in
    some.
    """
    # the simulator (torch) is loaded here, not for the command's --help
    from avrisk.api.runs import EXPECTED, compare_runs, settings
    from avrisk.cli.run import show_outcome

    method = settings(
        "splitting_is",
        gamma=0.1,
        gamma_test=(0.2, 0.3, 0.5, 1.0),
        n_particles=rollouts // 10,
        n_final=rollouts // 2,
        seed=seed,
        batch_size=1024,
    )
    console.rule("bundled scenario highway_default: P(min TTC <= gamma)")
    with user_errors(*EXPECTED):
        result = compare_runs(
            "highway_default",
            out,
            method,
            reference_n=reference,
            failures=3,
            device="cpu",
            progress=RichProgress(err_console),
        )
        show_outcome(result, as_json=False)
