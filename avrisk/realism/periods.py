"""Part A by speed band, and held-out periods side by side (issue 44).

Periods of a day differ mostly in how congested they are (BENCHMARKS.md,
"Drivers on a period they never saw"). So that a left-out period's figures
can be read against the regime it was recorded in, part A is also summarised
by speed band: a held-out window is *congested* when its recorded leader's
mean speed is below :data:`CONGESTED_BELOW`, *flowing* otherwise
(:func:`window_bands`). The
band is a property of the window's record, so the humans and every model are
compared on the same windows; a band's figures are those of the replays of its
windows, taken from the same replays as the whole set's
(:meth:`~avrisk.realism.car_following.PartA.take_windows`). The bands are
:func:`avrisk.learning.replay.window_bands`'s, which training can weigh too.

:func:`band_summaries` gives each band's part-A summary and targets;
:func:`score_summary` the compact JSON of one report (every target with its
margin, overall and by band); :func:`periods_table` a markdown table with one
column per held-out set and band.
"""

from __future__ import annotations

from typing import Any, Protocol

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.learning.guard_fit import engagements, guard_conditions
from avrisk.learning.replay import BANDS, CONGESTED_BELOW, window_bands
from avrisk.realism.car_following import PartA, recorded, summarise_part_a
from avrisk.realism.metrics import event_rate
from avrisk.realism.targets import KS_METRICS, part_a_targets
from avrisk.sim import Road

__all__ = [
    "BANDS",
    "CONGESTED_BELOW",
    "band_summaries",
    "brake_use",
    "periods_table",
    "score_summary",
    "window_bands",
]


class RealismResult(Protocol):
    """What the tables read of :class:`avrisk.realism.report.RealismResult`.

    A protocol, so that this module (which the report imports) does not
    import the report back.
    """

    @property
    def settings(self) -> Any: ...  # noqa: D102
    @property
    def part_a(self) -> PartA: ...  # noqa: D102
    @property
    def targets(self) -> dict[str, Any]: ...  # noqa: D102
    @property
    def bands(self) -> dict[str, Any]: ...  # noqa: D102
    @property
    def summary_a(self) -> dict[str, Any]: ...  # noqa: D102
    @property
    def summary_b(self) -> dict[str, Any]: ...  # noqa: D102


def band_summaries(part: PartA, road: Road) -> dict[str, dict[str, Any]]:
    """Part A's summary and targets in each speed band that has windows.

    Parameters
    ----------
    part : PartA
    road : Road
        The road the windows were replayed on.

    Returns
    -------
    dict of str to dict
        Per band of :data:`BANDS` with at least one window: ``summary``
        (:func:`~avrisk.realism.car_following.summarise_part_a`) and
        ``targets`` (per model, :meth:`TargetResult.to_dict` of each).
    """
    bands = window_bands(part.windows)
    out = {}
    for band in BANDS:
        keep = bands == band
        if not keep.any():
            continue
        summary = summarise_part_a(part.take_windows(keep, road))
        targets = part_a_targets(summary)
        out[band] = {
            "summary": summary,
            "targets": {m: [t.to_dict() for t in ts] for m, ts in targets.items()},
        }
    return out


def brake_use(part: PartA, guard: BrakeGuard) -> dict[str, dict[str, Any]]:
    """How often ``guard``'s condition holds, for the humans and every model.

    Counted alike on the recorded followers and on the replays
    (:func:`~avrisk.learning.guard_fit.guard_conditions`): whether the
    replays drove with the brake or not, it is where it acts (or would).

    Returns
    -------
    dict of str to dict
        Per ``"human"`` and model name: ``onsets`` (episodes of the brake
        acting, :func:`~avrisk.learning.guard_fit.engagements`) as
        :func:`~avrisk.realism.metrics.event_rate` per vehicle-hour, and
        ``share``, the share of alive steps in which it acts.
    """
    rows = {"human": (recorded(part.windows), part.human.hours)}
    rows |= {n: (r, part.models[n].hours) for n, r in part.replays.items()}
    out = {}
    for name, (r, hours) in rows.items():
        acting = guard_conditions(guard, r.gap, r.v, r.v_l)
        out[name] = {
            "onsets": event_rate(engagements(acting, r.alive), hours),
            "share": float((acting & r.alive).sum() / max(r.alive.sum(), 1)),
        }
    return out


def _compact(summary: dict[str, Any], targets: dict[str, list[dict]]) -> dict:
    """One set's figures for the seed study: sizes, KS, rates, targets."""
    human, models = summary["human"], summary["models"]

    def figures(m: dict[str, Any]) -> dict[str, Any]:
        return {
            "ks": {k: m[k] and m[k].get("ks") for k in KS_METRICS},
            "p5": {k: m[k] and m[k]["p5"] for k in ("accel", "gap", "ttc")},
            "collisions_per_hour": m["collisions"]["per_hour"],
            "collisions": m["collisions"]["count"],
            "collisions_ci95_windows": m["collisions"].get("ci95_windows"),
            "hard_brakes_per_hour": m["hard_brakes"]["per_hour"],
            "time_stopped": m["time_stopped"],
        }

    return {
        "windows": summary["windows"],
        "human_vehicle_hours": human["vehicle_hours"],
        "human_median_speed": human["speed"] and human["speed"]["p50"],
        "human": figures(human) | {"ks": None},
        "models": {name: figures(m) for name, m in models.items()},
        "targets": {
            name: {
                t["target"]: {
                    "value": t["value"],
                    "passed": t["passed"],
                    "margin": t["margin"],
                }
                for t in ts
            }
            for name, ts in targets.items()
        },
        "all_passed": {
            name: all(t["passed"] for t in ts) for name, ts in targets.items()
        },
    }


def score_summary(
    result: RealismResult, brake: BrakeGuard | None = None
) -> dict[str, Any]:
    """A realism report's figures in brief: the whole set and each band.

    Parameters
    ----------
    result : RealismResult
    brake : BrakeGuard, optional
        Count where this brake acts (:func:`brake_use`) in each set; default
        the one the report drove with (none if it drove without).

    Returns
    -------
    dict
        ``held_out``, ``guard`` (the brake driven with, or None), ``all`` and
        one entry per band of :attr:`RealismResult.bands`: windows,
        vehicle-hours, the humans' median speed, per model the KS statistics,
        the 5th percentiles, the rates, every target with its margin
        (:attr:`~avrisk.realism.targets.TargetResult.margin`) and, with a
        brake, ``brake_use``; ``lane_changes``: part B's rates against the
        held-out humans'.
    """
    guard = result.settings.guard
    brake = guard if brake is None else brake
    part, road = result.part_a, Road()
    targets = {m: [t.to_dict() for t in ts] for m, ts in result.targets.items()}
    sets = {"all": (part, result.summary_a, targets)}
    bands = window_bands(part.windows)
    for band, v in result.bands.items():
        sets[band] = (
            part.take_windows(bands == band, road),
            v["summary"],
            v["targets"],
        )
    out: dict[str, Any] = {
        "held_out": result.settings.held_out,
        "guard": None if guard is None else guard.to_dict(),
        "brake_counted": None if brake is None else brake.to_dict(),
    }
    for name, (p, summary, t) in sets.items():
        out[name] = _compact(summary, t)
        if brake is not None:
            out[name]["brake_use"] = brake_use(p, brake)
    b = result.summary_b
    out["lane_changes"] = {
        "human_per_hour": b["human_held_out"]["rate"],
        "models": {
            n: {k: m[k] for k in ("rate", "vs_held_out", "target_met")}
            for n, m in b["models"].items()
        },
    }
    return out


def _column_title(result: RealismResult, band: str) -> str:
    summary = result.summary_a if band == "all" else result.bands[band]["summary"]
    speed = summary["human"]["speed"]["p50"]
    where = result.settings.held_out
    return f"{where}, {band} ({summary['windows']} windows, median {speed:.1f} m/s)"


def periods_table(results: list[RealismResult], model: str = "learned xi~P0") -> str:
    """Markdown: one column per held-out set and band, one row per target.

    Parameters
    ----------
    results : list of RealismResult
        E.g. one per fold of a leave-one-period-out validation, each scored
        on its left-out period.
    model : str, default="learned xi~P0"
        The learned model shown.
    """
    columns = []
    for r in results:
        columns.append((r, "all", r.targets[model]))
        for band, v in r.bands.items():
            rows = v["summary"]
            columns.append((r, band, part_a_targets(rows)[model]))
    lines = [
        f"**Part A by held-out set and speed band** ({model}; a window is "
        f"congested when its leader's mean speed is below {CONGESTED_BELOW:g} "
        "m/s)",
        "",
        "| target | " + " | ".join(_column_title(r, b) for r, b, _ in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for i, first in enumerate(columns[0][2]):
        cells = [
            f"{ts[i].text} {'pass' if ts[i].passed else 'FAIL'}" for *_, ts in columns
        ]
        lines.append(f"| {first.target} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
