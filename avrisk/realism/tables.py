"""The realism report's markdown tables, from the figures of the summaries.

Every number printed comes from the JSON-ready summaries
(:func:`~avrisk.realism.car_following.summarise_part_a`,
:func:`~avrisk.realism.targets.part_a_targets`,
:func:`~avrisk.realism.lane_changes.summarise_lane_changes`), so that
``realism.md`` and ``realism.json`` always agree.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from avrisk.realism.car_following import QUANTITIES
from avrisk.realism.lane_changes import N_VEHICLES
from avrisk.realism.targets import TargetResult

__all__ = [
    "collision_table",
    "lane_change_table",
    "part_a_table",
    "quantile_cell",
    "targets_table",
]

#: Row labels of the distributions, where not the quantity's key.
LABELS = {
    "ttc": "TTC (closing only, capped 20 s)",
    "offset": "lateral offset (lateral-file windows)",
}


def quantile_cell(q: dict[str, float] | None) -> str:
    """``"p5 / p50 / p95"`` to two decimals, ``"n/a"`` without samples."""
    if q is None:
        return "n/a"
    return f"{q['p5']:.2f} / {q['p50']:.2f} / {q['p95']:.2f}"


def _distance_cell(q: dict[str, float] | None) -> str:
    if q is None or "ks" not in q:
        return "n/a"
    return f"{q['ks']:.3f} / {q['w1']:.3g}"


def _row(label: str, human: str, cells: list[str]) -> str:
    return f"| {label} | {human} | " + " | ".join(cells) + " |"


def part_a_table(summary: dict[str, Any]) -> str:
    """Part A: percentiles, KS / W1 to the humans, rates, per model."""
    human, models = summary["human"], summary["models"]
    model_hours = next(iter(models.values()))["vehicle_hours"]
    lines = [
        f"**A. Car following on held-out NGSIM I-80** ({summary['windows']} "
        f"windows of {summary['window_s']:.0f} s, {human['vehicle_hours']:.2f} "
        f"vehicle-hours of humans; each driven {summary['replicates']} time(s) "
        f"by every model: {model_hours:.1f} vehicle-hours; leader replayed; "
        "KS / W1 vs human)",
        "",
        "| metric | human (held out) | " + " | ".join(models) + " |",
        "|---|---|" + "---|" * len(models),
    ]
    lines += _distribution_rows(human, models)
    lines += _rate_rows(summary, human, models)
    return "\n".join(lines)


def _distribution_rows(
    human: dict[str, Any], models: dict[str, dict[str, Any]]
) -> list[str]:
    """Each quantity's percentiles, then its KS / W1 distance to the humans."""
    lines = []
    for key, unit in QUANTITIES.items():
        label = LABELS.get(key, key)
        lines.append(
            _row(
                f"{label} [{unit}] p5/p50/p95",
                quantile_cell(human[key]),
                [quantile_cell(m[key]) for m in models.values()],
            )
        )
        lines.append(
            _row(
                f"{label}: KS / W1",
                "-",
                [_distance_cell(m[key]) for m in models.values()],
            )
        )
    return lines


def _rate_rows(
    summary: dict[str, Any], human: dict[str, Any], models: dict[str, dict[str, Any]]
) -> list[str]:
    """Hard brakes, lane changes, collisions, departures per hour; the gap's RMSE."""

    def rate(key: str) -> list[str]:
        return [f"{m[key]['per_hour']:.1f}" for m in models.values()]

    collisions = [m["collisions"] for m in models.values()]
    return [
        _row(
            "hard brakes (< -3 m/s^2) [1/veh-h]",
            f"{human['hard_brakes']['per_hour']:.1f}",
            rate("hard_brakes"),
        ),
        _row(
            "lane changes [1/veh-h]",
            f"{human['lane_changes']['per_hour']:.1f} (single-lane episodes)",
            rate("lane_changes"),
        ),
        _row(
            "collisions with the leader [1/veh-h] [95% CI] (count)",
            "0",
            [
                f"{c['per_hour']:.2f} [{c['ci95'][0]:.2f}, {c['ci95'][1]:.2f}] "
                f"({c['count']})"
                for c in collisions
            ],
        ),
        _row(
            "the same, windows as clusters [95% CI] (windows with collisions)",
            "0",
            [
                f"[{c['ci95_windows'][0]:.2f}, {c['ci95_windows'][1]:.2f}] "
                f"({c['windows_with_events']} of {c['windows']})"
                for c in collisions
            ],
        ),
        _row(
            "road departures [1/veh-h]",
            f"{human['road_departures']['per_hour']:.1f}",
            rate("road_departures"),
        ),
        _row(
            f"RMSE of the gap after {summary['window_s']:.0f} s [m]",
            "0",
            [f"{m['gap_rmse_m']:.2f}" for m in models.values()],
        ),
    ]


def targets_table(targets: dict[str, list[TargetResult]]) -> str:
    """Issue 21's targets on part A: figure and pass/FAIL per learned model."""
    models = list(targets)
    lines = [
        "**Targets of issue 21 on part A** (pass = meets the target)",
        "",
        "| target | " + " | ".join(models) + " |",
        "|---|" + "---|" * len(models),
    ]
    for row in zip(*targets.values(), strict=True):
        cells = [f"{t.text} {'pass' if t.passed else 'FAIL'}" for t in row]
        lines.append(f"| {row[0].target} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def collision_table(summary: dict[str, Any]) -> str:
    """Where part A's collisions with the leader happen, per model."""
    lines = [
        "**Collisions of part A, per model** (medians over the collisions; "
        "windows by held-out index, with their number of collisions)",
        "",
        "| model | collisions | windows | speed at impact [m/s] | leader speed "
        "[m/s] | hardest decel before [m/s^2] | human's in the same windows "
        "[m/s^2] | leader near stop [-] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, m in summary["models"].items():
        rows = np.asarray(m["impacts"]["rows"], dtype=float).reshape(-1, 7)
        if not len(rows):
            lines.append(f"| {name} | 0 | - | - | - | - | - | - |")
            continue
        w, count = np.unique(rows[:, 0].astype(int), return_counts=True)
        top = ", ".join(
            f"{i}: {c}"
            for i, c in sorted(zip(w, count, strict=True), key=lambda p: -p[1])[:6]
        )
        med = np.median(rows, axis=0)
        lines.append(
            f"| {name} | {len(rows)} | {len(w)} ({top}) | {med[2]:.1f} | "
            f"{med[3]:.1f} | {med[4]:.2f} | {med[5]:.2f} | {rows[:, 6].mean():.2f} |"
        )
    return "\n".join(lines)


def _q(s: dict[str, Any], name: str, digits: int) -> str:
    values = [s[f"{name}_q{q}"] for q in (10, 50, 90)]
    if any(v is None for v in values):
        return "-"
    return " / ".join(f"{v:.{digits}f}" for v in values)


def lane_change_table(
    summary: dict[str, Any], scenes: int, horizon: float, seed: int
) -> str:
    """Part B: lane changes and collisions per model against held-out US-101.

    Parameters
    ----------
    summary : dict
        :func:`~avrisk.realism.lane_changes.summarise_lane_changes`.
    scenes : int
        Scenes simulated per model.
    horizon : float
        Their length [s].
    seed : int
        Their seed.
    """
    human = summary["human_held_out"]
    lines = [
        f"**B. Lane changes** ({scenes} random six-lane scenes x {N_VEHICLES} "
        f"vehicles x {horizon:g} s, seed {seed}; learned drivers with xi ~ P0 "
        "per scene; target: within +-30% of the held-out rate)",
        "",
        "| drivers | lane changes [1/veh-h] (95% CI) | vs held-out | duration "
        "p10/50/90 [s] | peak lateral speed p10/50/90 [m/s] | collisions "
        "[1/veh-h] | lane-change collisions [1/veh-h] (95% CI) |",
        "|---|---|---|---|---|---|---|",
        f"| human, held-out US-101 ({human['hours']:.2f} veh-h) | "
        f"{human['rate']:.1f} [{human['rate_low']:.1f}, {human['rate_high']:.1f}] "
        f"| - | {_q(human, 'duration', 1)} | {_q(human, 'peak', 2)} | n/a | n/a |",
    ]
    for name, m in summary["models"].items():
        lcc = m["lc_collisions"]
        lines.append(
            f"| {name} | {m['rate']:.1f} [{m['rate_low']:.1f}, "
            f"{m['rate_high']:.1f}] | {m['vs_held_out']:+.0%} "
            f"{'pass' if m['target_met'] else 'FAIL'} | {_q(m, 'duration', 1)} | "
            f"{_q(m, 'peak', 2)} | {m['collisions']['per_hour']:.2f} | "
            f"{lcc['per_hour']:.2f} [{lcc['ci95'][0]:.2f}, {lcc['ci95'][1]:.2f}] |"
        )
    return "\n".join(lines)
