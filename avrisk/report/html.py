"""The HTML report of one or more runs (Jinja2 template, relative image links).

The report reads only what runs leave behind (``summary.json``,
``samples.parquet``) plus images drawn next to it, so ``avrisk report DIR``
can rebuild it at any time. It leads with one answer
(:func:`avrisk.report.answer.headline`): the probability per rollout, its
interval, the method and whether the estimator's own diagnostics trust it.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pyarrow.compute as pc

from avrisk.pipeline.files import write_atomic
from avrisk.pipeline.store import BOOKKEEPING, DENSITIES, RunDirectory
from avrisk.rare.estimator import estimator_class
from avrisk.report.answer import (
    headline,
    run_trust,
    search_sentence,
    threshold_trust,
)
from avrisk.report.failures import failure_view, p0_log_density_sample
from avrisk.report.plots import (
    UNRELIABLE_MARK,
    UNRELIABLE_NOTE,
    comparison_rows,
    plot_comparison,
    plot_diagnostic,
    table_cells,
)
from avrisk.scenario import ScenarioSpec

#: Sections of the report, in order (a golden list for tests).
SECTIONS = ("answer", "runs", "comparison", "failures", "settings")


def top_failures(run_dir: RunDirectory, gamma: float, k: int) -> list[dict[str, Any]]:
    """The ``k`` rollouts with ``f <= gamma`` of highest ``log p0``, of all stages.

    Returns
    -------
    list of dict
        Samples-table rows, most likely first.
    """
    table = run_dir.samples(["f", "log_p0"])
    hits = np.flatnonzero(pc.less_equal(table["f"], gamma).to_numpy())
    if hits.size == 0:
        return []
    log_p0 = table["log_p0"].to_numpy()[hits]
    order = hits[np.argsort(-log_p0, kind="stable")[:k]]
    return run_dir.samples(rows=order).to_pylist()  # only these rows drawn again


def _run_view(
    label: str,
    run_dir: RunDirectory,
    diagnostics: list[str],
    tables: list[dict[str, Any]],
) -> dict[str, Any]:
    summary = run_dir.summary()
    est = summary["estimate"]
    timing = summary["timing"]
    rate = timing.get("rollouts_per_second")
    search = estimator_class(summary["method"]).convergence(est, est["gamma"])
    by_gamma = [  # older summaries have no pareto_k
        {"pareto_k": None, **g, "trust": threshold_trust(summary, g)}
        for g in sorted(est["by_gamma"], key=lambda g: g["gamma"])
    ]
    return {
        "label": label,
        "gamma": est["gamma"],
        "p": est["p"],
        "stderr": est["stderr"],
        "ci": est["ci"],
        "n_hits": est["n_hits"],
        "ess": est["ess"] or 0.0,
        "n_evals": est["n_evals"],
        "by_gamma": by_gamma,
        "trust": run_trust(summary),
        "interval": next(g for g in by_gamma if g["gamma"] == est["gamma"]).get(
            "interval"  # absent from older summaries
        ),
        "timing": (
            f"{timing['wall_time_s']:.1f} s wall time; "
            f"{timing['rollouts_evaluated']:,} rollouts evaluated"
            + (f" at {rate:,.0f} rollouts/s" if rate else "")
            + (
                f", {timing['rollouts_replayed']:,} replayed from an earlier session"
                if timing["rollouts_replayed"]
                else ""
            )
        ),
        "diagnostics": diagnostics,
        "tables": tables,
        # a search that did not converge is a reason of the run's trust
        "search": search_sentence(search) if search and search.converged else None,
        "mechanisms": next(
            (
                m["by_label"]
                for m in (summary.get("mechanisms") or {}).get("by_gamma", [])
                if m["gamma"] == est["gamma"]
            ),
            [],
        ),
    }


def write_report(
    out_dir: Path,
    runs: Sequence[tuple[str, RunDirectory]],
    *,
    title: str,
    subtitle: str = "",
    reference: RunDirectory | None = None,
    failures_from: RunDirectory | None = None,
    n_failures: int = 6,
    param_names: Sequence[str] = (),
    animate: Callable[[dict[str, Any], Path], Path | None] | None = None,
    spec: ScenarioSpec | None = None,
) -> Path:
    """Draw the plots and write ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : Path
        Where ``report.html`` and ``plots/`` go.
    runs : sequence of (label, RunDirectory)
        Complete runs to show, in order, the run under test first; each gets
        its estimator's diagnostics (plots, and tables of those it does not
        draw), and the first importance-weighted one is compared with naive
        sampling.
    title, subtitle : str
    reference : RunDirectory, optional
        A large naive run whose estimates serve as ``p`` in the comparison.
    failures_from : RunDirectory, optional
        Run whose samples provide the most likely failures.
    n_failures : int
        How many failures to show.
    param_names : sequence of str
        Scenario parameters to list with each failure (without ``spec``).
    animate : callable, optional
        ``animate(row, path)`` writes an animation of a samples-table row and
        returns its path (or ``None``).
    spec : ScenarioSpec, optional
        The runs' scenario: gives the time base of ``p`` (its horizon [s]),
        and each failure's vehicles at absolute positions with the percentile
        of its ``log p0`` under P0. Without it the answer is per rollout and
        failures list their parameters as recorded.

    Returns
    -------
    Path
        The report file.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = out_dir / "plots"
    views, weighted = [], None
    for i, (label, run_dir) in enumerate(runs):
        summary = run_dir.summary()
        estimator = estimator_class(summary["method"])
        images, tables = [], []
        for j, table in enumerate(estimator.diagnostics(summary["estimate"])):
            if not table.drawn:
                tables.append(
                    {
                        "title": table.title,
                        "columns": table.columns,
                        "rows": table_cells(table),
                    }
                )
                continue
            name = f"diagnostics_{i}_{j}.png"
            plot_diagnostic(table, summary["estimate"]["gamma"], plots / name)
            images.append(f"plots/{name}")
        if estimator.weighted and weighted is None:
            weighted = (label, summary)
        views.append(_run_view(label, run_dir, images, tables))
    comparison = None
    if weighted is not None:
        ref = reference.summary()["estimate"] if reference is not None else None
        plot_comparison(
            weighted[1]["estimate"], weighted[0], plots / "comparison.png", ref
        )
        comparison = {
            "label": weighted[0],
            "n_evals": weighted[1]["estimate"]["n_evals"],
            "plot": "plots/comparison.png",
            "rows": comparison_rows(weighted[1]["estimate"], ref),
            "has_reference": ref is not None,
            "note": UNRELIABLE_NOTE,
        }
    failures, gamma = [], None
    if failures_from is not None:
        gamma = failures_from.summary()["estimate"]["gamma"]
        rows = top_failures(failures_from, gamma, n_failures)
        p0_sample = p0_log_density_sample(spec) if spec is not None and rows else None
        for j, row in enumerate(rows):
            anim = (
                animate(row, out_dir / "animations" / f"failure_{j + 1}.gif")
                if animate
                else None
            )
            failures.append(
                failure_view(
                    row,
                    spec,
                    p0_sample,
                    names=[n for n in param_names if n in row]
                    or [n for n in row if n not in BOOKKEEPING + DENSITIES],
                    units=failures_from.units,
                    animation=str(anim.relative_to(out_dir)) if anim else None,
                )
            )
    first = runs[0][1]
    answer = headline(
        [(label, d.summary()) for label, d in runs],
        spec.simulation.horizon if spec is not None else None,
    )
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("avrisk.report", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]),
    )
    html = env.get_template("report.html.j2").render(
        title=title,
        subtitle=subtitle,
        answer=answer,
        runs=views,
        comparison=comparison,
        mark=UNRELIABLE_MARK,
        failures=failures,
        failures_gamma=gamma,
        camera=spec is not None and spec.camera is not None,
        settings={**first.config().get("settings", {})},
        footer=f"avrisk {first.summary()['versions']['avrisk']} - "
        f"generated {dt.datetime.now().isoformat(timespec='seconds')}",
    )
    path = out_dir / "report.html"
    write_atomic(path, html)  # a full disk leaves no half-written report
    return path
