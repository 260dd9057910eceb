"""What ``run``, ``compare``, ``ab`` and ``report`` print: the answer, tables, or JSON.

The terminal gets the one answer first (:func:`avrisk.report.answer.headline`,
the same as the report's), then a table per run that fits 80 columns (Rich
wraps the text cells of a narrower terminal). With ``--json``, stdout gets one
JSON document instead (:func:`avrisk.api.document.result_document`, schema
``avrisk.result/1``);
progress, warnings and notes stay on stderr, so stdout parses. An A/B
comparison prints its one line (or its ``avrisk.ab/1`` document).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.markup import escape

from avrisk.api.document import Runs, answer, mechanisms, result_document
from avrisk.cli.common import err_console, out_console
from avrisk.cli.tables import add_columns, compact_table
from avrisk.pipeline.files import json_text
from avrisk.rare.estimator import estimator_class
from avrisk.rare.trust import estimate_diagnostics
from avrisk.report.answer import run_trust, search_remark, threshold_trust
from avrisk.report.plots import UNRELIABLE_MARK, UNRELIABLE_NOTE, table_cells
from avrisk.scenario import ScenarioSpec

if TYPE_CHECKING:  # the comparison's module loads the simulator (torch)
    from avrisk.api.ab import ABResult


def print_summary(runs: Runs, spec: ScenarioSpec) -> None:
    """The answer in one sentence, then every run's estimate at every threshold.

    After each run's table: how its search ended (unless that is a reason of
    its trust), its trust when not ok (the answer's reasons
    are in the answer), and the tables of its estimator's diagnostics that
    the report does not draw (splitting_is: its proposal, and the estimate
    beside subset simulation's own).
    """
    lead = answer(runs, spec)
    out_console.print(f"[bold]{escape(lead.sentence())}[/]", highlight=False)
    out_console.print(escape(lead.time_base()), highlight=False)
    for label, run_dir in runs:
        summary = run_dir.summary()
        est = summary["estimate"]
        table = compact_table(
            f"{label}, {est['n_evals']:,} rollouts: P(min TTC <= gamma) per rollout",
            f"95% interval: {_interval(est)}" if _interval(est) else None,
        )
        names = ["gamma [s]", "p", "stderr", "95% CI", "hits", "ESS", "Pareto k"]
        add_columns(table, [*names, "trust"], text=["trust"])
        for g in sorted(est["by_gamma"], key=lambda g: g["gamma"]):
            table.add_row(
                f"{g['gamma']:g}",
                f"{g['p']:.3g}",
                f"{g['stderr']:.2g}",
                f"{g['ci'][0]:.2g}..{g['ci'][1]:.2g}",
                str(g["n_hits"]),
                f"{g['ess'] or 0:.1f}",
                "-" if g.get("pareto_k") is None else f"{g['pareto_k']:.2f}",
                threshold_trust(summary, g).word,
            )
        out_console.print(table)
        trust = run_trust(summary)
        remark = search_remark(summary, trust)
        if remark is not None:
            out_console.print(f"{escape(label)}: {escape(remark)}", highlight=False)
        if not trust.ok and label != lead.label:  # the answer's reasons are above
            out_console.print(
                f"{escape(label)}: trust at {est['gamma']:g} s: {escape(str(trust))}",
                highlight=False,
            )
        if est.get("stopped_by", "budget") != "budget":
            rule = est["stopped_by"].replace("_", " ")
            out_console.print(
                f"{escape(label)}: stopped by its {rule} rule after "
                f"{est['n_evals']:,} rollouts",
                highlight=False,
            )
        print_mechanisms(label, summary)
        print_diagnostic_tables(label, summary)


def print_diagnostic_tables(label: str, summary: dict[str, Any]) -> None:
    """The diagnostic tables of a run's estimator that are not drawn, as tables."""
    estimator = estimator_class(summary["method"])
    for diagnostic in estimate_diagnostics(estimator, summary["estimate"]):
        if diagnostic.drawn:
            continue
        table = compact_table(f"{label}: {diagnostic.title}")
        add_columns(table, diagnostic.columns)
        for row in table_cells(diagnostic):
            table.add_row(*row)
        out_console.print(table)


def _interval(est: dict[str, Any]) -> str | None:
    """How the main threshold's interval was computed (absent from older runs)."""
    main = next(g for g in est["by_gamma"] if g["gamma"] == est["gamma"])
    return main.get("interval") or None


def print_mechanisms(label: str, summary: dict[str, Any]) -> None:
    """What the dangerous rollouts were, at the run's main threshold: p by mechanism."""
    parts = mechanisms(summary)
    if not parts:
        return
    gamma = summary["estimate"]["gamma"]
    table = compact_table(f"{label}: P(min TTC <= {gamma:g} s) by what happened")
    add_columns(
        table, ["what happened", "p", "95% CI", "share", "hits"], text=["what happened"]
    )
    for part in parts:
        share = part["share"]
        table.add_row(
            part["label"],
            f"{part['p']:.3g}",
            f"{part['ci'][0]:.2g}..{part['ci'][1]:.2g}",
            "-" if share is None else f"{share:.0%}",
            str(part["n_hits"]),
        )
    out_console.print(table)


def print_failed(runs: Runs) -> None:
    """One warning line on stderr per run with rollouts that failed to evaluate."""
    for label, run_dir in runs:
        by_gamma = run_dir.summary()["estimate"]["by_gamma"]
        failed = max((g.get("n_failed", 0) for g in by_gamma), default=0)
        if failed:
            err_console.print(
                f"[yellow]warning:[/] {escape(label)}: {failed} rollouts failed to "
                "evaluate; p counts them safe, the interval reaches up to counting "
                "them dangerous (rerun the command to evaluate them again)",
                highlight=False,
            )


def print_ratios(
    label: str, n_rollouts: int, rows: list[dict[str, Any]], has_reference: bool
) -> None:
    """The method against naive MC at the same budget, per threshold (Fig. 2-3)."""
    caption = (
        "Naive figures are expected values (n p hits, variance p(1-p)/n) with p "
        + (
            "from the naive reference run (the method's own where it saw no hit)"
            if has_reference
            else "the method's own estimate (no reference run)"
        )
        + ". The variance ratio trusts the method's own standard error; the spread "
        "over seeds (benchmarks/ce_vs_naive.py) is the stricter test."
    )
    if not all(row["reliable"] for row in rows):
        caption += " " + UNRELIABLE_NOTE + "."
    table = compact_table(
        f"{label} against naive Monte Carlo, both with {n_rollouts:,} rollouts",
        caption,
    )
    add_columns(
        table,
        [
            "gamma\n[s]",
            "p\nused",
            "method\nhits",
            "naive hits\nseen",
            "naive hits\nexpected",
            "rare-event\nratio",
            "variance\nratio",
        ],
    )
    for row in rows:
        table.add_row(
            f"{row['gamma']:g}",
            f"{row['p']:.3g}",
            str(row["hits"]),
            str(row["naive_hits_seen"] if row["naive_hits_seen"] is not None else ""),
            f"{row['naive_hits_expected']:.1f}",
            f"{row['rare_event_ratio']:.1f}x",
            f"{row['variance_ratio']:.1f}x"
            + ("" if row["reliable"] else UNRELIABLE_MARK),
        )
    out_console.print(table)


def show_results(
    command: str,
    runs: Runs,
    spec: ScenarioSpec,
    *,
    as_json: bool = False,
    ratios: list[dict[str, Any]] | None = None,
    has_reference: bool = False,
    report: Path | None = None,
) -> None:
    """The results of ``command``: tables on stdout, or one JSON document.

    Parameters
    ----------
    command : str
        ``"run"``, ``"compare"`` or ``"report"``.
    runs : list of (label, RunDirectory)
        Complete runs, the one under test first.
    spec : ScenarioSpec
        Their scenario.
    as_json : bool, default=False
        Print :func:`~avrisk.api.document.result_document` instead of tables.
    ratios : list of dict, optional
        :func:`~avrisk.api.document.ratio_rows` of a comparison.
    has_reference : bool, default=False
        Whether the comparison has a naive reference run (for ``ratios``).
    report : Path, optional
        The report written (named on stderr).
    """
    if as_json:
        print_json(result_document(command, runs, spec, ratios=ratios, report=report))
    else:
        print_summary(runs, spec)
        if ratios is not None:
            est = runs[0][1].summary()["estimate"]
            print_ratios(runs[0][0], est["n_evals"], ratios, has_reference)
    print_failed(runs)
    if report is not None:
        name_report(report)


def show_comparison(result: ABResult, as_json: bool) -> None:
    """An A/B comparison: its line on stdout, or its document; its report named."""
    if as_json:
        print_json(result.document())
    else:
        out_console.print(result.line(), highlight=False, soft_wrap=True)
    if result.report is not None:
        name_report(result.report)


def name_report(report: Path) -> None:
    """The report's path, on stderr."""
    err_console.print(  # a path is never broken
        f"report: {escape(str(report))}", highlight=False, soft_wrap=True
    )


def print_json(doc: dict[str, Any]) -> None:
    """``doc`` on stdout as one JSON document (plain, no Rich markup)."""
    sys.stdout.write(json_text(doc))
    sys.stdout.flush()
