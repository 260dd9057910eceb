"""``avrisk demo``: the main job of the README, in a few minutes.

Both parts are :func:`avrisk.api.demo.run_demo`'s:

1. The estimation engine against problems with exact answers: at an equal
   budget of calls of ``f``, how far naive Monte Carlo and the cross-entropy
   method land from the exact probability (a table on stdout, with the
   cross-entropy runs' bars).
2. The bundled default scenario: importance sampling from subset
   simulation's particles (``splitting_is``, the estimator whose intervals
   cover the large reference there) and naive Monte Carlo at the same budget
   of rollouts, and a larger naive reference (``avrisk compare``: the paper's
   Table 1 and Fig. 2-3), with the run directories and the HTML report under
   ``--scenario-out``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import typer
from rich.table import Table

from avrisk.api.demo import MIN_BUDGET, ExactEstimates, run_demo
from avrisk.api.events import Event
from avrisk.cli.common import (
    check_output_file,
    check_output_folder,
    err_console,
    out_console,
    user_errors,
)
from avrisk.cli.progress import RichProgress
from avrisk.cli.tables import add_columns, compact_table
from avrisk.rare import Estimate
from avrisk.testing import AnalyticProblem

METHOD_LABELS = {"naive_mc": "naive MC", "cross_entropy": "CE"}


def analytic_table(
    budget: int,
    seed: int,
    results: Sequence[tuple[AnalyticProblem, Sequence[Estimate]]],
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
        min=MIN_BUDGET,
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
    # the simulator (torch) is loaded here, not for the command's --help
    from avrisk.api.runs import EXPECTED
    from avrisk.cli.run import show_outcome

    with user_errors(*EXPECTED):
        result = run_demo(
            budget=budget,
            seed=seed,
            out=out,
            scenario_out=scenario_out,
            rollouts=rollouts,
            reference=reference,
            progress=DemoDisplay(show_rule=rollouts > 0),
        )
        if result.scenario is not None:
            show_outcome(result.scenario, as_json=False)


class DemoDisplay:
    """The demo's progress: the exact part on stdout, the scenario's on stderr.

    The cross-entropy runs' bars go to stdout above their table; once the
    :class:`~avrisk.api.demo.ExactEstimates` come, the table and, before the
    scenario part (``show_rule``), its heading; the scenario's runs then show
    as ``avrisk compare``'s do.
    """

    def __init__(self, show_rule: bool) -> None:
        self.show_rule = show_rule
        self.runs = RichProgress(out_console)

    def __call__(self, event: Event | ExactEstimates) -> None:
        """Show ``event``."""
        if not isinstance(event, ExactEstimates):
            self.runs(event)
            return
        out_console.print(analytic_table(event.budget, event.seed, event.problems))
        out_console.print(
            "Naive Monte Carlo needs about 1/(p eps^2) calls for relative error "
            "eps; cross-entropy importance sampling reaches a few percent with "
            "the same budget."
        )
        if event.written is not None:
            out_console.print(f"wrote {event.written}")
        if self.show_rule:
            out_console.rule("bundled scenario highway_default: P(min TTC <= gamma)")
        self.runs = RichProgress(err_console)
