"""Plots of a run, drawn from its ``summary.json`` alone (Matplotlib, Agg).

* :func:`plot_comparison` -- the paper's Fig. 2/3: against each test threshold,
  the ratio of the number of rare events (the method's final-stage hits over the
  naive hits expected with its whole budget of rollouts) and the ratio of
  estimator variances (naive over the method, at that budget).
* :func:`plot_diagnostic` -- an estimator's per-step diagnostics (for CE:
  ``gamma_k`` and the ``rho``-quantile per iteration, with its hits);
  :func:`table_cells` -- those it gives as a table instead, as text.

Ratios use expected naive figures, ``n p`` hits and variance ``p (1 - p) / n``
with ``p`` the best estimate at hand (a reference run when given, else the
method's own), because a naive run at a 1e-6 event mostly sees zero hits and its ratio
would be infinite or undefined.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from avrisk.rare.estimator import DiagnosticTable
from avrisk.rare.final_stage import MIN_RELIABLE_ESS, is_reliable
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K

#: Marks a figure computed from an unreliable importance-sampling standard error.
UNRELIABLE_MARK = "*"
UNRELIABLE_NOTE = (
    f"{UNRELIABLE_MARK} fewer than {MIN_RELIABLE_ESS:g} effective hits of the method, "
    f"or hit weights with a heavy tail (Pareto k > {MAX_RELIABLE_PARETO_K:g}), at "
    "this threshold: its standard error, hence the variance ratio, is unreliable"
)


def comparison_rows(
    tested: dict[str, Any], reference: dict[str, Any] | None = None
) -> list[dict[str, Any]]:
    """Per test threshold: the method's hits, expected naive hits and the two ratios.

    The comparison is at an equal budget: naive Monte Carlo with as many
    rollouts as the method used in all (``n_evals``, a CE search or subset
    simulation's levels included), against the method's final-stage hits and
    standard error. Both ratios are thus conservative for the method: the
    hits of its search are not counted.

    Parameters
    ----------
    tested : dict
        ``estimate`` section of a weighted run's summary (CE, splitting_is).
    reference : dict, optional
        ``estimate`` section of a (large) naive run, used for ``p`` when it has
        hits at that threshold.

    Returns
    -------
    list of dict
        Keys ``gamma``, ``p``, ``p_from`` (``"reference"`` or ``"own"``: where
        ``p`` comes from), ``hits`` (the method's), ``naive_hits_expected``,
        ``rare_event_ratio``, ``variance_ratio``, and ``reliable``: whether the
        method's standard error there can be trusted
        (:func:`avrisk.rare.final_stage.is_reliable`; else the variance ratio
        means little).
    """
    ref = {g["gamma"]: g for g in (reference or {}).get("by_gamma", [])}
    rows = []
    for g in tested["by_gamma"]:
        r = ref.get(g["gamma"])
        p_from = "reference" if r is not None and r["n_hits"] > 0 else "own"
        p = r["p"] if p_from == "reference" else g["p"]
        n = tested["n_evals"]
        naive_hits = n * p
        naive_var = p * (1 - p) / n
        stderr = g["stderr"] or 0.0
        rows.append(
            {
                "gamma": g["gamma"],
                "p": p,
                "p_from": p_from,
                "hits": g["n_hits"],
                "naive_hits_expected": naive_hits,
                "rare_event_ratio": g["n_hits"] / naive_hits
                if naive_hits > 0
                else np.nan,
                "variance_ratio": naive_var / stderr**2 if stderr > 0 else np.nan,
                "reliable": is_reliable(g.get("ess"), g.get("pareto_k")),
            }
        )
    return sorted(rows, key=lambda row: row["gamma"])


def _pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend, imported on first use.

    Matplotlib takes about half a second to import; the commands that print
    tables without drawing (``run``, ``compare``, ``simulate``) do not pay it.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_comparison(
    tested: dict[str, Any],
    label: str,
    path: Path,
    reference: dict[str, Any] | None = None,
) -> Path:
    """Draw the rare-event ratio and the variance ratio against the threshold.

    ``label`` names the method (``"cross-entropy"``, ``"splitting + IS"``).
    """
    plt = _pyplot()
    rows = comparison_rows(tested, reference)
    gammas = [r["gamma"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    panels = (
        ("rare_event_ratio", f"rare events: {label} / naive (same budget)"),
        ("variance_ratio", f"variance: naive / {label} (same budget)"),
    )
    for ax, (key, title) in zip(axes, panels, strict=True):
        ax.plot(gammas, [r[key] for r in rows], "o-", color="tab:blue")
        shaky = [r for r in rows if not r["reliable"]]
        if key == "variance_ratio" and shaky:
            ax.plot(
                [r["gamma"] for r in shaky],
                [r[key] for r in shaky],
                "o",
                mfc="white",
                mec="tab:red",
                ms=9,
                label=f"{label}: standard error unreliable",
            )
            ax.legend(fontsize="small")
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_xlabel("threshold gamma [s]")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def table_cells(table: DiagnosticTable) -> list[tuple[str, ...]]:
    """The rows of a diagnostic table as text, for a report or a terminal.

    Integers with thousands separators, other numbers to 3 significant
    digits, a ``(low, high)`` pair as ``low..high``, a missing or non-finite
    value as ``-``.

    Examples
    --------
    >>> row = (2000, 0.012345, [1e-4, 2e-4], None)
    >>> table_cells(DiagnosticTable("t", ("a", "b", "c", "d"), [row]))
    [('2,000', '0.0123', '0.0001..0.0002', '-')]
    """

    def cell(value: Any) -> str:
        if isinstance(value, list | tuple):
            return "..".join(cell(v) for v in value)
        if isinstance(value, int) and not isinstance(value, bool):
            return f"{value:,}"
        if isinstance(value, float):
            return f"{value:.3g}" if np.isfinite(value) else "-"
        return "-" if value is None else str(value)

    return [tuple(cell(v) for v in row) for row in table.rows]


def plot_diagnostic(
    table: DiagnosticTable, gamma: float, path: Path, unit: str = "s"
) -> Path:
    """Draw an estimator's per-step diagnostics: lines over steps, bars below.

    Parameters
    ----------
    table : DiagnosticTable
        From the estimator's ``diagnostics``.
    gamma : float
        Threshold, marked on the top panel [``unit``].
    path : Path
        PNG to write.
    unit : str, default="s"
        Unit of ``f``.
    """
    from matplotlib.ticker import MaxNLocator

    plt = _pyplot()
    steps = table.column(table.columns[0])
    panels = 2 if table.bars else 1
    fig, axes = plt.subplots(
        panels,
        1,
        figsize=(7, 2.5 + 2.5 * panels),
        sharex=True,
        squeeze=False,
        constrained_layout=True,
    )
    ax = axes[0, 0]
    for name, style in zip(table.lines, ("o-", "s--", "^:", "v-."), strict=False):
        ax.plot(steps, table.column(name), style, label=name)
    ax.axhline(gamma, color="tab:red", lw=1, label=f"gamma = {gamma:g}")
    ax.set_ylabel(f"f [{unit}]")
    ax.set_title(table.title)
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(True, alpha=0.3)
    if table.bars:
        below = axes[1, 0]
        below.bar(steps, table.column(table.bars), color="tab:orange")
        below.set_ylabel(table.bars)
        below.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts
        below.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel(table.columns[0])
    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))  # step numbers
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
