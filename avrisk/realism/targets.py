"""Issue 21's targets on part A: each learned model's figure and pass or fail.

The targets, on the held-out I-80 windows (:mod:`avrisk.realism.car_following`):

* collisions with the leader at most 0.5 per vehicle-hour;
* acceleration 5th and 10th percentiles within 15% of the humans';
* gap and TTC 5th percentiles within 10% of the humans';
* the share of time stopped (speed < 0.1 m/s) within 25% of the humans';
* closer to the humans than IDM on at least 7 of 9 metrics. Part A has 8 of
  them: the KS statistic of speed, acceleration, jerk, gap and TTC, and the
  absolute difference of the rates of hard brakes, collisions and road
  departures (equal to the humans' counts as closer); the ninth, lane changes,
  is part B's. 7 of the 8 meet the target whatever part B's lane changes do;
* issue 44's: the TTC KS statistic below IDM's (closing like the humans, not
  only on average).

Percentile targets are relative distances to the humans' percentile
(:func:`~avrisk.realism.metrics.relative_gap`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from avrisk.realism.metrics import relative_gap

__all__ = ["TargetResult", "part_a_targets"]

#: Distributions compared by KS for the "closer than IDM" target.
KS_METRICS = ("speed", "accel", "jerk", "gap", "ttc")
#: Rates compared by their absolute difference to the humans'.
RATE_METRICS = ("hard_brakes", "collisions", "road_departures")


@dataclass(frozen=True)
class TargetResult:
    """One target for one model.

    Attributes
    ----------
    target : str
        What is asked, e.g. ``"gap p5 within 10%"``.
    value : float or None
        The model's figure (None without samples).
    human : float or None
        The humans' (None where the target is not relative to them).
    passed : bool
    figure : str
        ``value`` as the tables show it, e.g. ``"4.19"`` (``"n/a"`` for None).
    human_figure : str or None
        ``human`` likewise.
    margin : float or None
        How far inside the target the figure is, in the target's own terms
        (negative: outside): the limit less the rate, the tolerance less the
        relative distance, the metrics closer than IDM less 7, IDM's KS less
        the model's. None without samples.
    """

    target: str
    value: float | None
    human: float | None
    passed: bool
    figure: str
    human_figure: str | None = None
    margin: float | None = None

    @property
    def text(self) -> str:
        """The figure with the humans', e.g. ``"4.19 (human 3.45)"``."""
        if self.human_figure is None:
            return self.figure
        return f"{self.figure} (human {self.human_figure})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return asdict(self)


def _percentile_target(
    key: str, p: str, label: str, tol: float
) -> Callable[[dict, dict, dict], TargetResult]:
    def check(model: dict, human: dict, _: dict) -> TargetResult:
        name = f"{label} {p} within {tol:.0%}"
        if model[key] is None or human[key] is None:
            return TargetResult(name, None, None, False, "n/a")
        a, b = model[key][p], human[key][p]
        margin = tol - relative_gap(a, b)
        return TargetResult(name, a, b, margin >= 0, f"{a:.2f}", f"{b:.2f}", margin)

    return check


def _collisions(model: dict, human: dict, _: dict) -> TargetResult:
    rate = model["collisions"]["per_hour"]
    return TargetResult(
        "collisions <= 0.5 /veh-h",
        rate,
        None,
        rate <= 0.5,
        f"{rate:.2f}",
        margin=0.5 - rate,
    )


def _stopped(model: dict, human: dict, _: dict) -> TargetResult:
    a, b = model["time_stopped"], human["time_stopped"]
    margin = 0.25 - relative_gap(a, b)
    return TargetResult(
        "time stopped within 25%", a, b, margin >= 0, f"{a:.3f}", f"{b:.3f}", margin
    )


def _ks(figures: dict, key: str) -> float | None:
    return figures[key].get("ks") if figures[key] is not None else None


def _closer(model: dict, human: dict, reference: dict) -> TargetResult:
    wins = 0
    for key in KS_METRICS:
        ks, ks_ref = _ks(model, key), _ks(reference, key)
        wins += ks is not None and ks_ref is not None and ks < ks_ref
    for key in RATE_METRICS:
        h = human[key]["per_hour"]  # measured on the record like the models
        d = abs(model[key]["per_hour"] - h)
        d_ref = abs(reference[key]["per_hour"] - h)
        wins += d < d_ref or d == 0
    return TargetResult(
        "closer to humans than IDM (8 of the 9 metrics)",
        float(wins),
        None,
        wins >= 7,
        f"{wins} of 8",
        margin=float(wins - 7),
    )


def _ttc_ks(model: dict, human: dict, reference: dict) -> TargetResult:
    ks, ks_ref = _ks(model, "ttc"), _ks(reference, "ttc")
    name = "TTC KS below IDM's"
    if ks is None or ks_ref is None:
        return TargetResult(name, None, None, False, "n/a")
    figure = f"{ks:.3f} (IDM {ks_ref:.3f})"
    return TargetResult(name, ks, None, ks < ks_ref, figure, margin=ks_ref - ks)


#: The checks, in the order of the tables.
CHECKS = (
    _collisions,
    _percentile_target("accel", "p5", "accel", 0.15),
    _percentile_target("accel", "p10", "accel", 0.15),
    _percentile_target("gap", "p5", "gap", 0.10),
    _percentile_target("ttc", "p5", "TTC", 0.10),
    _stopped,
    _closer,
    _ttc_ks,
)


def part_a_targets(
    summary: dict[str, Any], reference: str = "IDM"
) -> dict[str, list[TargetResult]]:
    """Every target for every model of part A but ``reference``.

    Parameters
    ----------
    summary : dict
        :func:`~avrisk.realism.car_following.summarise_part_a`.
    reference : str, default="IDM"
        The model the "closer to humans" target compares with.

    Returns
    -------
    dict of str to list of TargetResult
        Per model, the targets in the order of the module docstring.
    """
    models, human = summary["models"], summary["human"]
    ref = models[reference]
    return {
        name: [check(fig, human, ref) for check in CHECKS]
        for name, fig in models.items()
        if name != reference
    }
