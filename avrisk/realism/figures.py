"""The realism report's figures (PNG, matplotlib's Agg backend).

* :func:`draw_part_a`: empirical CDFs of part A's six distributions, humans
  in black against every model;
* :func:`draw_lane_changes`: part B's lane-change rate with its 95% interval
  against the held-out humans' (and the +-30% band of the target), and the
  CDFs of the manoeuvres' duration and peak lateral speed.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from avrisk.realism.car_following import PartA
from avrisk.realism.lane_changes import RATE_TOLERANCE, TrafficLaneChanges

__all__ = ["FIGURE_PANELS", "draw_lane_changes", "draw_part_a"]

#: Quantities of the figure of part A, with their labels and plotted ranges.
FIGURE_PANELS = {
    "speed": ("speed [m/s]", (0.0, 20.0)),
    "accel": ("acceleration [m/s^2]", (-3.0, 3.0)),
    "jerk": ("jerk [m/s^3]", (-5.0, 5.0)),
    "gap": ("gap to the leader [m]", (0.0, 60.0)),
    "ttc": ("TTC, closing only [s]", (0.0, 20.0)),
    "offset": ("lateral offset [m]", (-1.0, 1.0)),
}

#: Resolution of the PNGs [dots per inch].
DPI = 110


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _cdf(ax: Any, x: NDArray[Any], **style: Any) -> None:
    """The empirical CDF of ``x`` on ``ax``."""
    x = np.sort(np.asarray(x, dtype=float))
    ax.plot(x, np.arange(1, x.size + 1) / x.size, **style)


def draw_part_a(part: PartA, path: str | Path) -> None:
    """Empirical CDFs of part A's quantities: humans (black) vs each driver model."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5))
    panels = FIGURE_PANELS.items()
    for ax, (key, (label, xlim)) in zip(axes.ravel(), panels, strict=True):
        _cdf(
            ax, part.human.samples[key], label="human (held out)", color="black", lw=2.0
        )
        for name, f in part.models.items():
            _cdf(ax, f.samples[key], label=name)
        ax.set_xlim(*xlim)
        ax.set_xlabel(label)
        ax.set_ylabel("fraction <= x")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(
        "Car following on held-out NGSIM I-80 windows: learned drivers and IDM "
        "against humans"
    )
    with warnings.catch_warnings():
        # The legend's best place is sought among 10^5-10^6 points: slow, not wrong.
        warnings.filterwarnings("ignore", message="Creating legend with loc=.best.")
        fig.tight_layout()
        fig.savefig(path, dpi=DPI)
    plt.close(fig)


def draw_lane_changes(
    summary: dict[str, Any],
    results: dict[str, TrafficLaneChanges],
    human_duration: NDArray[np.float64],
    human_peak: NDArray[np.float64],
    path: str | Path,
) -> None:
    """Part B: rate with interval per model, and the manoeuvres' distributions.

    Parameters
    ----------
    summary : dict
        :func:`~avrisk.realism.lane_changes.summarise_lane_changes`.
    results : dict of str to TrafficLaneChanges
        The models' changes (:func:`~avrisk.realism.lane_changes.evaluate`).
    human_duration, human_peak : ndarray of shape (K,)
        Duration [s] and peak lateral speed [m/s] of the held-out humans'
        changes.
    path : str or Path
        The PNG.
    """
    plt = _pyplot()
    fig, (ax_rate, ax_dur, ax_peak) = plt.subplots(
        1, 3, figsize=(13, 4.6), gridspec_kw={"width_ratios": [1.3, 1, 1]}
    )
    human = summary["human_held_out"]
    rows = [("human, held-out US-101", human)] + list(summary["models"].items())
    y = np.arange(len(rows))[::-1]
    ax_rate.axvspan(
        human["rate"] * (1 - RATE_TOLERANCE),
        human["rate"] * (1 + RATE_TOLERANCE),
        color="0.85",
        label=f"target: held-out rate +-{RATE_TOLERANCE:.0%}",
    )
    # One colour per model in every panel (C0, C1, ...), the humans in black.
    colors = ["black"] + [f"C{i}" for i in range(len(rows) - 1)]
    for yy, (_, s), color in zip(y, rows, colors, strict=True):
        ax_rate.errorbar(
            s["rate"],
            yy,
            xerr=[[s["rate"] - s["rate_low"]], [s["rate_high"] - s["rate"]]],
            fmt="o",
            capsize=4,
            color=color,
        )
    ax_rate.set_yticks(y, [_wrapped(name) for name, _ in rows], fontsize=8)
    ax_rate.set_xlabel("lane changes [1/veh-h], 95% CI")
    ax_rate.set_xlim(left=-2.0)  # a rate of 0 stays in view
    ax_rate.grid(alpha=0.3, axis="x")
    ax_rate.legend(fontsize=8, loc="lower right")
    for ax, x_human, field, label in (
        (ax_dur, human_duration, "duration", "duration of a change [s]"),
        (ax_peak, human_peak, "peak_lateral_speed", "peak lateral speed [m/s]"),
    ):
        _cdf(ax, x_human, label="human, held-out US-101", color="black", lw=2.0)
        for (name, m), color in zip(results.items(), colors[1:], strict=True):
            if len(m.changes):
                _cdf(ax, getattr(m.changes, field), label=name, color=color)
        ax.set_xlabel(label)
        ax.set_ylabel("fraction <= x")
        ax.grid(alpha=0.3)
    # Below the panels: inside, it would hide the distributions' bends.
    fig.legend(
        *ax_dur.get_legend_handles_labels(), loc="lower center", ncol=4, fontsize=8
    )
    fig.suptitle(
        "Lane changes in six-lane traffic: learned drivers and IDM+MOBIL against "
        "held-out US-101 vehicles"
    )
    fig.tight_layout(rect=(0.0, 0.06, 1.0, 1.0))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _wrapped(name: str) -> str:
    """A model's name over two lines at its parenthesis."""
    return name.replace(" (", "\n(")
