"""The HTML report of one or more runs (Jinja2 template, relative image links).

The report reads only what runs leave behind (``summary.json``,
``samples.parquet``) plus images drawn next to it, so ``avrisk report DIR``
can rebuild it at any time.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pyarrow.compute as pc

from avrisk.pipeline.files import write_atomic
from avrisk.pipeline.store import BOOKKEEPING, DENSITIES, RunDirectory
from avrisk.rare.estimator import estimator_class
from avrisk.rare.final_stage import MIN_RELIABLE_ESS, is_reliable
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K
from avrisk.report.plots import (
    UNRELIABLE_MARK,
    UNRELIABLE_NOTE,
    comparison_rows,
    plot_comparison,
    plot_diagnostic,
)
from avrisk.scenario.params import XI_PREFIX

#: Sections of the report, in order (a golden list for tests).
SECTIONS = ("runs", "comparison", "failures", "settings")


@dataclass(frozen=True)
class Failure:
    """A dangerous rollout as the report shows it.

    Attributes
    ----------
    row : dict
        Its row of the samples table (scenario parameters by name, ``f``,
        ``log_p0``, ``seed``, ...).
    animation : str or None
        Path of its animation, relative to the report.
    """

    row: dict[str, Any]
    animation: str | None = None


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
    label: str, run_dir: RunDirectory, diagnostics: list[str]
) -> dict[str, Any]:
    summary = run_dir.summary()
    est = summary["estimate"]
    timing = summary["timing"]
    rate = timing.get("rollouts_per_second")
    main = next(g for g in est["by_gamma"] if g["gamma"] == est["gamma"])
    weighted = estimator_class(summary["method"]).weighted
    warning = None
    if main["n_hits"] == 0:
        warning = (
            "No rollout reached the threshold: the estimate is 0 and the interval is "
            "an upper bound only."
        )
    elif not weighted and main["n_hits"] < MIN_RELIABLE_ESS:
        warning = (
            f"Only {main['n_hits']} hits: the relative standard error is about "
            f"{1 / math.sqrt(main['n_hits']):.0%}."
        )
    elif (main["ess"] or 0) < MIN_RELIABLE_ESS:
        warning = (
            f"Only {main['ess']:.1f} effective hits: a few weights dominate, so the "
            "standard error is unreliable."
        )
    elif not is_reliable(main["ess"], main.get("pareto_k")):
        warning = (
            f"The hits' weights have a heavy tail (Pareto k = {main['pareto_k']:.2f} "
            f"> {MAX_RELIABLE_PARETO_K:g}): the standard error is unreliable, likely "
            "too small; compare runs with other seeds."
        )
    by_gamma = [
        {
            "pareto_k": None,  # summaries written before it was recorded
            **g,
            "reliable": not weighted or is_reliable(g["ess"], g.get("pareto_k")),
        }
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
        "warning": warning,
        "interval": main.get("interval"),  # absent from older summaries
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
) -> Path:
    """Draw the plots and write ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : Path
        Where ``report.html`` and ``plots/`` go.
    runs : sequence of (label, RunDirectory)
        Complete runs to show, in order; each gets its estimator's diagnostic
        plots, and the first importance-weighted one is compared with naive
        sampling.
    title, subtitle : str
    reference : RunDirectory, optional
        A large naive run whose estimates serve as ``p`` in the comparison.
    failures_from : RunDirectory, optional
        Run whose samples provide the most likely failures.
    n_failures : int
        How many failures to show.
    param_names : sequence of str
        Scenario parameters to list with each failure.
    animate : callable, optional
        ``animate(row, path)`` writes an animation of a samples-table row and
        returns its path (or ``None``).

    Returns
    -------
    Path
        The report file.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = out_dir / "plots"
    views, ce_summary = [], None
    for i, (label, run_dir) in enumerate(runs):
        summary = run_dir.summary()
        estimator = estimator_class(summary["method"])
        images = []
        for j, table in enumerate(estimator.diagnostics(summary["estimate"])):
            name = f"diagnostics_{i}_{j}.png"
            plot_diagnostic(table, summary["estimate"]["gamma"], plots / name)
            images.append(f"plots/{name}")
        if estimator.weighted:
            ce_summary = ce_summary or summary
        views.append(_run_view(label, run_dir, images))
    comparison = None
    if ce_summary is not None:
        ref = reference.summary()["estimate"] if reference is not None else None
        plot_comparison(ce_summary["estimate"], plots / "comparison.png", ref)
        comparison = {
            "plot": "plots/comparison.png",
            "rows": comparison_rows(ce_summary["estimate"], ref),
            "mark": UNRELIABLE_MARK,
            "note": UNRELIABLE_NOTE,
        }
    failures, gamma = [], None
    if failures_from is not None:
        gamma = failures_from.summary()["estimate"]["gamma"]
        for j, row in enumerate(top_failures(failures_from, gamma, n_failures)):
            anim = (
                animate(row, out_dir / "animations" / f"failure_{j + 1}.gif")
                if animate
                else None
            )
            failures.append(_failure_view(row, param_names, anim, out_dir))
    first = runs[0][1]
    settings = {**first.config().get("settings", {})}
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("avrisk.report", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]),
    )
    html = env.get_template("report.html.j2").render(
        title=title,
        subtitle=subtitle,
        runs=views,
        comparison=comparison,
        mark=UNRELIABLE_MARK,
        failures=failures,
        failures_gamma=gamma,
        settings=settings,
        footer=f"avrisk {first.summary()['versions']['avrisk']} - "
        f"generated {dt.datetime.now().isoformat(timespec='seconds')}",
    )
    path = out_dir / "report.html"
    write_atomic(path, html)  # a full disk leaves no half-written report
    return path


def _failure_view(
    row: dict[str, Any], names: Sequence[str], anim: Path | None, out_dir: Path
) -> dict[str, Any]:
    skip = set(BOOKKEEPING + DENSITIES)
    shown = [n for n in names if n in row] or [n for n in row if n not in skip]
    # The driver network's hundreds of weights are no reading for a person.
    n_xi = sum(n.startswith(XI_PREFIX) for n in shown)
    shown = [n for n in shown if not n.startswith(XI_PREFIX)]
    params = ", ".join(f"{n}={row[n]:.3g}" for n in shown if isinstance(row[n], float))
    if n_xi:
        params += f" (and {n_xi} driver-network weights {XI_PREFIX}*)"
    return {
        "f": row["f"],
        "crash": bool(row.get("crash", False)),
        "log_p0": row["log_p0"],
        "phase": row["phase"],
        "sample_id": row["sample_id"],
        "animation": str(anim.relative_to(out_dir)) if anim is not None else None,
        "params": params,
    }
