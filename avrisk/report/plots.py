"""Plots of a run, drawn from its ``summary.json`` alone (Matplotlib, Agg).

* :func:`plot_comparison` -- the paper's Fig. 2/3: against each test threshold,
  the ratio of the number of rare events (CE's final-stage hits over the naive
  hits expected with CE's whole budget of rollouts) and the ratio of estimator
  variances (naive over CE, at that budget).
* :func:`plot_ce_trajectory` -- ``gamma_k`` and the ``rho``-quantile per CE
  iteration, with the hits of each iteration.

Ratios use expected naive figures, ``n p`` hits and variance ``p (1 - p) / n``
with ``p`` the best estimate at hand (a reference run when given, else CE's
own), because a naive run at a 1e-6 event mostly sees zero hits and its ratio
would be infinite or undefined.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from avrisk.rare.final_stage import MIN_RELIABLE_ESS, is_reliable  # noqa: E402
from avrisk.rare.weights import MAX_RELIABLE_PARETO_K  # noqa: E402

#: Marks a figure computed from an unreliable CE standard error.
UNRELIABLE_MARK = "*"
UNRELIABLE_NOTE = (
    f"{UNRELIABLE_MARK} fewer than {MIN_RELIABLE_ESS:g} effective CE hits, or hit "
    f"weights with a heavy tail (Pareto k > {MAX_RELIABLE_PARETO_K:g}), at this "
    "threshold: CE's standard error, hence the variance ratio, is unreliable"
)


def comparison_rows(
    ce: dict[str, Any], reference: dict[str, Any] | None = None
) -> list[dict[str, float]]:
    """Per test threshold: CE hits, expected naive hits and the two ratios.

    The comparison is at an equal budget: naive Monte Carlo with as many
    rollouts as CE used in all (``n_evals``, search iterations included),
    against CE's final-stage hits and standard error. Both ratios are thus
    conservative for CE: the hits of its search iterations are not counted.

    Parameters
    ----------
    ce : dict
        ``estimate`` section of a CE run's summary.
    reference : dict, optional
        ``estimate`` section of a (large) naive run, used for ``p`` when it has
        hits at that threshold.

    Returns
    -------
    list of dict
        Keys ``gamma``, ``p``, ``ce_hits``, ``naive_hits_expected``,
        ``rare_event_ratio``, ``variance_ratio``, and ``reliable``: whether CE's
        standard error there can be trusted
        (:func:`avrisk.rare.final_stage.is_reliable`; else the variance ratio
        means little).
    """
    ref = {g["gamma"]: g for g in (reference or {}).get("by_gamma", [])}
    rows = []
    for g in ce["by_gamma"]:
        r = ref.get(g["gamma"])
        p = r["p"] if r is not None and r["n_hits"] > 0 else g["p"]
        n = ce["n_evals"]
        naive_hits = n * p
        naive_var = p * (1 - p) / n
        stderr = g["stderr"] or 0.0
        rows.append(
            {
                "gamma": g["gamma"],
                "p": p,
                "ce_hits": g["n_hits"],
                "naive_hits_expected": naive_hits,
                "rare_event_ratio": g["n_hits"] / naive_hits
                if naive_hits > 0
                else np.nan,
                "variance_ratio": naive_var / stderr**2 if stderr > 0 else np.nan,
                "reliable": is_reliable(g.get("ess"), g.get("pareto_k")),
            }
        )
    return sorted(rows, key=lambda row: row["gamma"])


def plot_comparison(
    ce: dict[str, Any], path: Path, reference: dict[str, Any] | None = None
) -> Path:
    """Draw the rare-event ratio and the variance ratio against the threshold."""
    rows = comparison_rows(ce, reference)
    gammas = [r["gamma"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    panels = (
        ("rare_event_ratio", "rare events: CE / naive (same budget)"),
        ("variance_ratio", "variance: naive / CE (same budget)"),
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
                label="CE's standard error unreliable",
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


def plot_ce_trajectory(history: list[dict[str, Any]], gamma: float, path: Path) -> Path:
    """Draw ``gamma_k``, the ``rho``-quantile and the hits per CE iteration."""
    it = [h["iteration"] for h in history]
    fig, (ax, ax_hits) = plt.subplots(
        2, 1, figsize=(7, 5), sharex=True, constrained_layout=True
    )
    ax.plot(it, [h["quantile"] for h in history], "o-", label="rho-quantile of f")
    ax.plot(it, [h["gamma_k"] for h in history], "s--", label="gamma_k")
    ax.axhline(gamma, color="tab:red", lw=1, label=f"gamma = {gamma:g}")
    ax.set_ylabel("f [s]")
    ax.set_title("Cross-entropy search")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax_hits.bar(it, [h["n_hits"] for h in history], color="tab:orange")
    ax_hits.set_ylabel("samples with f <= gamma")
    ax_hits.set_xlabel("CE iteration")
    ax_hits.grid(True, alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
