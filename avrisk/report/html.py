"""The HTML report of one or more runs (Jinja2 template, relative image links).

The report reads only what runs leave behind (``summary.json``,
``samples.parquet``) plus images drawn next to it, so ``avrisk report DIR``
can rebuild it at any time. It leads with one answer
(:func:`avrisk.report.answer.headline`): the probability per rollout, its
interval, the method and whether the estimator's own diagnostics trust it;
then the most likely failures with their animations; then how the estimate
was made (each run's estimates, its estimator's diagnostics, the comparison
with naive sampling, every run's settings), each table explained where it
appears, for a reader who does not know the methods.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pyarrow.compute as pc

from avrisk.assembly import Typicality, scenario_typicality
from avrisk.pipeline.files import write_atomic
from avrisk.pipeline.samples import BOOKKEEPING, DENSITIES
from avrisk.pipeline.store import RunDirectory
from avrisk.rare.estimator import estimator_class
from avrisk.rare.final_stage import MIN_RELIABLE_ESS
from avrisk.rare.trust import estimate_diagnostics
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K
from avrisk.report.answer import (
    headline,
    run_trust,
    search_remark,
    threshold_trust,
)
from avrisk.report.failures import failure_view
from avrisk.report.plots import (
    UNRELIABLE_MARK,
    UNRELIABLE_NOTE,
    comparison_rows,
    plot_comparison,
    plot_diagnostic,
    table_cells,
)
from avrisk.scenario import ScenarioSpec

#: Sections of the report, in order (a golden list for tests): the answer and
#: the failures first, how the estimate was made below them.
SECTIONS = ("answer", "failures", "statistics", "runs", "comparison", "settings")


#: Each method in plain words, as a report explains the run that used it.
METHODS = {
    "naive": (
        "Naive Monte Carlo: rollouts from situations drawn from P0; p is the share "
        "that are dangerous. Unbiased and simple, but a rare event needs many "
        "rollouts to be seen at all."
    ),
    "splitting": (
        "Subset simulation (splitting): reaches the rare event in steps (levels), "
        "each keeping the rollouts closest to danger and growing new ones from "
        "them; p is the product of the shares kept (plot below)."
    ),
    "splitting_is": (
        "Splitting + IS: subset simulation first finds the dangerous situations "
        "in steps (levels, plots below), in independent replicates; then "
        "importance sampling (IS) draws fresh rollouts from a distribution "
        "fitted to them and weights each by how much more often P0 than that "
        "distribution would draw it, so that the weighted share of dangerous "
        "rollouts is an unbiased estimate of p."
    ),
    "ce": (
        "Cross-entropy: a search moves the distribution rollouts are drawn from "
        "towards danger, iteration by iteration (plot below); the final stage "
        "draws from it and weights each rollout by how much more often P0 than "
        "that distribution would draw it (importance sampling)."
    ),
}
METHODS["defensive"] = METHODS["mixture"] = METHODS["ce"]


def top_failures(
    run_dir: RunDirectory, gamma: float, k: int, typical: Typicality | None = None
) -> list[dict[str, Any]]:
    """The ``k`` most likely rollouts with ``f <= gamma``, of all stages.

    Ranked by :meth:`Typicality.rank` (the lower of the start's and the
    drivers' percentiles under P0, ties by ``log p0``) when ``typical`` is
    given, else (a black box with no scenario) by ``log p0``.

    Returns
    -------
    list of dict
        Samples-table rows, most likely first.
    """
    start = list(typical.columns) if typical is not None else []
    table = run_dir.samples(["f", "log_p0", *start])
    hits = np.flatnonzero(pc.less_equal(table["f"], gamma).to_numpy())
    if hits.size == 0:
        return []
    log_p0 = table["log_p0"].to_numpy()[hits]
    if typical is None:
        key = log_p0[:, None]
    else:
        situation = np.stack([table[c].to_numpy()[hits] for c in start], axis=1)
        key = typical.rank(situation, log_p0)
    # highest key first; lexsort sorts by its last key first, ascending
    order = hits[np.lexsort(-key.T[::-1])[:k]]
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
    trust = run_trust(summary)
    by_gamma = [  # older summaries have no pareto_k
        {"pareto_k": None, **g, "trust": threshold_trust(summary, g)}
        for g in sorted(est["by_gamma"], key=lambda g: g["gamma"])
    ]
    return {
        "label": label,
        "method": METHODS.get(summary["method"], ""),
        "gamma": est["gamma"],
        "p": est["p"],
        "stderr": est["stderr"],
        "ci": est["ci"],
        "n_hits": est["n_hits"],
        "ess": est["ess"] or 0.0,
        "n_evals": est["n_evals"],
        "by_gamma": by_gamma,
        "trust": trust,
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
        "search": search_remark(summary, trust),
        "mechanisms": next(
            (
                m["by_label"]
                for m in (summary.get("mechanisms") or {}).get("by_gamma", [])
                if m["gamma"] == est["gamma"]
            ),
            [],
        ),
    }


def percentile_text(value: float) -> str:
    """A percentile as a failure card shows it: ``"47"``, ``"3.2"``, ``"< 0.01"``.

    Examples
    --------
    >>> [percentile_text(v) for v in (99.7, 3.24, 0.123, 0.0)]
    ['100', '3.2', '0.12', '< 0.01']
    """
    if value >= 10:
        return f"{value:.0f}"
    if value >= 1:
        return f"{value:.1f}"
    return f"{value:.2f}" if value >= 0.01 else "< 0.01"


def settings_table(runs: Sequence[tuple[str, RunDirectory]]) -> dict[str, Any]:
    """Every run's settings side by side: ``labels`` and ``rows`` of text.

    One row per setting any run has (in the order they first appear), one
    cell per run, ``"-"`` where a run's method has no such setting.
    """
    each = [d.config().get("settings", {}) for _, d in runs]
    names = list(dict.fromkeys(name for settings in each for name in settings))

    def text(value: Any) -> str:
        if isinstance(value, list):
            return ", ".join(text(v) for v in value)
        if value is None:
            return "-"
        return f"{value:,}" if type(value) is int else str(value)

    return {
        "labels": [label for label, _ in runs],
        "rows": [
            (name, [text(s[name]) if name in s else "-" for s in each])
            for name in names
        ],
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
        and each failure's vehicles at absolute positions with the
        percentiles of its start and its drivers under P0, by which failures
        are ranked. Without it the answer is per rollout and failures, ranked
        by ``log p0``, list their parameters as recorded.

    Returns
    -------
    Path
        The report file.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = out_dir / "plots"
    views, weighted = _run_views(runs, plots)
    comparison = _comparison(weighted, reference, plots)
    typical = scenario_typicality(spec) if spec is not None else None
    failures, gamma = [], None
    if failures_from is not None:
        gamma = failures_from.summary()["estimate"]["gamma"]
        failures = _failure_views(
            failures_from, n_failures, typical, spec, param_names, animate, out_dir
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
    env.filters["pct"] = percentile_text
    html = env.get_template("report.html.j2").render(
        title=title,
        subtitle=subtitle,
        answer=answer,
        runs=views,
        comparison=comparison,
        mark=UNRELIABLE_MARK,
        weighted=weighted is not None,
        min_ess=MIN_RELIABLE_ESS,
        max_k=MAX_RELIABLE_PARETO_K,
        failures=failures,
        failures_gamma=gamma,
        failures_label=runs[0][0],
        scenario=spec is not None,
        has_drivers=bool(typical and typical.drivers_dim),
        camera=spec is not None and spec.camera is not None,
        settings=settings_table(runs),
        footer=f"avrisk {first.summary()['versions']['avrisk']} - "
        f"generated {dt.datetime.now().isoformat(timespec='seconds')}",
    )
    path = out_dir / "report.html"
    write_atomic(path, html)  # a full disk leaves no half-written report
    return path


def _run_views(
    runs: Sequence[tuple[str, RunDirectory]], plots: Path
) -> tuple[list[dict[str, Any]], tuple[str, dict[str, Any]] | None]:
    """Each run's view with its diagnostics drawn into ``plots``.

    Also the first importance-weighted run, ``(label, summary)``, or None.
    """
    views, weighted = [], None
    for i, (label, run_dir) in enumerate(runs):
        summary = run_dir.summary()
        estimator = estimator_class(summary["method"])
        images, tables = [], []
        for j, table in enumerate(estimate_diagnostics(estimator, summary["estimate"])):
            if not table.drawn:
                tables.append(
                    {
                        "title": table.title,
                        "columns": table.columns,
                        "rows": table_cells(table),
                        "note": table.note,
                    }
                )
                continue
            name = f"diagnostics_{i}_{j}.png"
            plot_diagnostic(table, summary["estimate"]["gamma"], plots / name)
            images.append({"src": f"plots/{name}", "note": table.note})
        if estimator.weighted and weighted is None:
            weighted = (label, summary)
        views.append(_run_view(label, run_dir, images, tables))
    return views, weighted


def _comparison(
    weighted: tuple[str, dict[str, Any]] | None,
    reference: RunDirectory | None,
    plots: Path,
) -> dict[str, Any] | None:
    """The weighted run against naive sampling (and ``reference``), drawn."""
    if weighted is None:
        return None
    ref = reference.summary()["estimate"] if reference is not None else None
    plot_comparison(weighted[1]["estimate"], weighted[0], plots / "comparison.png", ref)
    return {
        "label": weighted[0],
        "n_evals": weighted[1]["estimate"]["n_evals"],
        "plot": "plots/comparison.png",
        "rows": comparison_rows(weighted[1]["estimate"], ref),
        "has_reference": ref is not None,
        "note": UNRELIABLE_NOTE,
    }


def _failure_views(
    run_dir: RunDirectory,
    n_failures: int,
    typical: Typicality | None,
    spec: ScenarioSpec | None,
    param_names: Sequence[str],
    animate: Callable[[dict[str, Any], Path], Path | None] | None,
    out_dir: Path,
) -> list[dict[str, Any]]:
    """The ``n_failures`` most likely failures of ``run_dir``, animated if asked."""
    estimate = run_dir.summary()["estimate"]
    estimator = estimator_class(run_dir.summary()["method"])
    rows = top_failures(run_dir, estimate["gamma"], n_failures, typical)
    failures = []
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
                typical,
                names=[n for n in param_names if n in row]
                or [n for n in row if n not in BOOKKEEPING + DENSITIES],
                units=run_dir.units,
                step=estimator.stage_label(estimate, row["stage"]),
                animation=str(anim.relative_to(out_dir)) if anim else None,
            )
        )
    return failures
