"""Measures of driving shared by the realism checks, on plain arrays.

A trajectory batch is an array of shape (N, T+1): ``N`` vehicles (or replayed
windows) at ``T + 1`` frames :data:`DT` apart, with a boolean ``alive`` of the
same shape (the frame was simulated; false after a collision ends a replay).
Samples are flat arrays of the frames that count; event counts are integers;
rates are counts over vehicle-hours.

Examples
--------
>>> import numpy as np
>>> v = np.array([[10.0, 10.0, 9.0, 8.0, 8.0]])   # one vehicle, 5 frames
>>> k = kinematics(v, np.ones_like(v, bool))
>>> k.accel.tolist()                               # [m/s^2]
[0.0, -10.0, -10.0, 0.0]
>>> hard_brake_events(k.accel_all, k.accel_ok)     # one episode below -3
1
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from avrisk.learning.ngsim.lane_changes import poisson_rate_interval

__all__ = [
    "DT",
    "HARD_BRAKE",
    "PERCENTILES",
    "STOPPED_SPEED",
    "TTC_CAP",
    "Kinematics",
    "clustered_event_rate",
    "event_rate",
    "hard_brake_events",
    "kinematics",
    "ks_w1",
    "lane_index_changes",
    "percentiles",
    "relative_gap",
    "road_departures",
    "stopped_fraction",
    "ttc_samples",
]

#: Frame interval of NGSIM and of the simulator [s].
DT = 0.1
#: Deceleration below which a frame is hard braking [m/s^2].
HARD_BRAKE = -3.0
#: Time-to-collision samples are capped here [s].
TTC_CAP = 20.0
#: Speed below which a vehicle counts as stopped [m/s].
STOPPED_SPEED = 0.1
#: Percentiles reported of every distribution.
PERCENTILES = (5, 10, 50, 95)


class Kinematics(NamedTuple):
    """Speed, acceleration and jerk of a trajectory batch.

    Attributes
    ----------
    speed : ndarray of shape (n_alive,)
        Speed of the alive frames [m/s].
    accel, jerk : ndarray of shape (n_a,), (n_j,)
        Finite differences over frames alive at both ends [m/s^2], [m/s^3].
    accel_all : ndarray of shape (N, T)
        Every acceleration, alive or not [m/s^2].
    accel_ok : ndarray of bool, shape (N, T)
        Where ``accel_all`` is between two alive frames.
    """

    speed: NDArray[np.float64]
    accel: NDArray[np.float64]
    jerk: NDArray[np.float64]
    accel_all: NDArray[np.float64]
    accel_ok: NDArray[np.bool_]


def kinematics(v: NDArray[Any], alive: NDArray[np.bool_]) -> Kinematics:
    """Speed, acceleration and jerk samples of ``v`` [m/s], shape (N, T+1)."""
    a = np.diff(v, axis=1) / DT
    j = np.diff(a, axis=1) / DT
    ok_a = alive[:, 1:] & alive[:, :-1]
    ok_j = ok_a[:, 1:] & ok_a[:, :-1]
    return Kinematics(v[alive], a[ok_a], j[ok_j], a, ok_a)


def ttc_samples(
    gap: NDArray[Any], v: NDArray[Any], v_l: NDArray[Any], alive: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """Time to collision with the leader at alive frames closing at > 0.05 m/s.

    Parameters
    ----------
    gap, v, v_l : ndarray of shape (N, T+1)
        Bumper gap [m], follower and leader speed [m/s].
    alive : ndarray of bool, shape (N, T+1)

    Returns
    -------
    ndarray of shape (n,)
        ``gap / (v - v_l)``, capped at :data:`TTC_CAP` [s].
    """
    closing = v - v_l
    m = alive & (closing > 0.05)
    return np.minimum(gap[m] / closing[m], TTC_CAP)


def hard_brake_events(accel: NDArray[Any], ok: NDArray[np.bool_]) -> int:
    """Episodes of hard braking: onsets of ``accel < HARD_BRAKE``, shape (N, T).

    A run of consecutive hard-braking frames of one vehicle is one event
    (one that is already under way at the first frame counts too).
    """
    hard = (accel < HARD_BRAKE) & ok
    onset = hard[:, 1:] & ~hard[:, :-1]
    return int(onset.sum() + hard[:, 0].sum())


def road_departures(
    y: NDArray[Any], half_width: NDArray[Any], road_width: float, alive: NDArray[Any]
) -> int:
    """Vehicles that cross a road edge: off the road after being on it.

    A vehicle is off the road at a frame when a side lies beyond an edge
    (``y - half_width < 0`` or ``y + half_width > road_width``; heading left
    out, so that recorded and simulated tracks are measured alike). A
    departure is a frame off the road after an alive frame on it; a vehicle
    counts once however often it leaves, and one that starts over an edge
    counts only if it comes back and leaves again.

    Parameters
    ----------
    y : ndarray of shape (N, T+1)
        Lateral position of the vehicle's centre [m].
    half_width : ndarray of shape (N,)
        Half its width [m].
    road_width : float
        [m]; the road spans ``0 <= y <= road_width``.
    alive : ndarray of bool, shape (N, T+1)

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> y = np.array([[1.2, 1.0, 0.8], [0.9, 1.5, 1.5]])  # one leaves, one returns
    >>> road_departures(y, np.array([1.0, 1.0]), 10.0, np.ones_like(y, bool))
    1
    """
    hw = np.asarray(half_width)[:, None]
    off = (y - hw < 0.0) | (y + hw > road_width)
    onset = off[:, 1:] & ~off[:, :-1] & alive[:, 1:] & alive[:, :-1]
    return int(onset.any(axis=1).sum())


def lane_index_changes(
    lane_pos: NDArray[Any], alive: NDArray[np.bool_], margin: float = 0.3
) -> int:
    """Changes of lane index with hysteresis, over alive frames.

    Parameters
    ----------
    lane_pos : ndarray of shape (N, T+1)
        Lateral position in lane widths (lane ``k`` is ``[k, k + 1)``).
    alive : ndarray of bool, shape (N, T+1)
    margin : float, default=0.3
        A vehicle in lane ``k`` has changed once it is more than ``margin``
        [lane widths] beyond the lane's edge.

    Returns
    -------
    int

    Examples
    --------
    >>> import numpy as np
    >>> pos = np.array([[0.5, 0.9, 1.2, 1.4, 1.5]])   # lane 0 to lane 1
    >>> lane_index_changes(pos, np.ones_like(pos, bool))
    1
    """
    count = 0
    for row, ok in zip(lane_pos, alive, strict=True):
        row = row[ok]
        if row.size == 0:
            continue
        cur = np.floor(row[0])
        for p in row:
            if p > cur + 1 + margin or p < cur - margin:
                count += 1
                cur = np.floor(p)
    return count


def ks_w1(sample: NDArray[Any], reference: NDArray[Any]) -> tuple[float, float] | None:
    """Kolmogorov-Smirnov statistic [-] and 1-Wasserstein distance of two samples.

    The distance is in the samples' unit; None where either is empty.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(10.0)
    >>> ks_w1(x, x)
    (0.0, 0.0)
    >>> ks, w1 = ks_w1(x, x + 100.0)
    >>> ks, round(w1, 6)
    (1.0, 100.0)
    """
    if sample.size == 0 or reference.size == 0:
        return None
    ks = stats.ks_2samp(sample, reference).statistic
    return float(ks), float(stats.wasserstein_distance(sample, reference))


def percentiles(x: NDArray[Any]) -> dict[str, float] | None:
    """The :data:`PERCENTILES` of ``x``: ``{"p5": ..., "p10": ...}``, None if empty."""
    if x.size == 0:
        return None
    q = np.percentile(x, PERCENTILES)
    return {f"p{p}": float(v) for p, v in zip(PERCENTILES, q, strict=True)}


def stopped_fraction(speed: NDArray[Any]) -> float:
    """Share of speed samples below :data:`STOPPED_SPEED` (NaN for none) [-]."""
    return float(np.mean(speed < STOPPED_SPEED)) if speed.size else float("nan")


def event_rate(count: int, hours: float) -> dict[str, Any]:
    """``count`` events in ``hours``: the count, the rate and its exact 95% interval.

    Returns
    -------
    dict
        ``count``, ``per_hour`` [1/h] and ``ci95`` (Garwood, ``[low, high]``
        [1/h], :func:`~avrisk.learning.ngsim.lane_changes.poisson_rate_interval`).

    Examples
    --------
    >>> event_rate(0, 2.0)["per_hour"], round(event_rate(0, 2.0)["ci95"][1], 3)
    (0.0, 1.844)
    """
    low, high = poisson_rate_interval(count, hours)
    return {"count": count, "per_hour": count / hours, "ci95": [low, high]}


def clustered_event_rate(counts: NDArray[Any], hours: float) -> dict[str, Any]:
    """Events counted per window, over its replays: the rate, with windows as clusters.

    The replays of one held-out window share its leader's record and its
    start, so their events are not independent draws of the traffic: a model
    that cannot stop behind one leader crashes in most of that window's
    replays. The exact Poisson interval of :func:`event_rate` treats every
    replay as independent and is then too narrow. This adds the quasi-Poisson
    interval over windows: with the per-window counts' dispersion ``phi =
    max(1, s^2 / mean)`` (``s^2`` their sample variance), ``C`` events in
    ``H`` hours weigh as ``C / phi`` independent events in ``H / phi`` hours
    (the design effect), whose Garwood interval is taken (an effective count
    need not be an integer). Without events there is no dispersion to
    measure and both intervals are the Poisson one; ``windows_with_events``
    of ``windows`` then says how few kinds of traffic were seen.

    Coverage of the true rate in simulated reports of 202 windows x 24
    replays, some windows crash-prone (2,000 reports per regime;
    ``benchmarks/collision_interval_coverage.py``, BENCHMARKS.md "Collision
    intervals when collisions cluster"): 0.97 for both intervals with
    independent replays; with 1-5% of windows crash-prone 0.85-0.96 against
    0.38-0.85 for the Poisson interval. When crash-prone windows are so rare
    that a third of reports see none (0.5%), no interval from such a report
    covers them (0.62 for both).

    Parameters
    ----------
    counts : ndarray of int, shape (W,)
        Events per window, summed over its replays (every window driven as
        often).
    hours : float
        Vehicle-hours of all ``W`` windows' replays together, ``> 0``.

    Returns
    -------
    dict
        :func:`event_rate`'s ``count``, ``per_hour`` [1/h] and ``ci95``
        (replays independent), and ``ci95_windows`` (windows as clusters)
        [1/h], ``dispersion`` (``phi``), ``windows`` (``W``) and
        ``windows_with_events``.

    Examples
    --------
    >>> import numpy as np
    >>> one_window = clustered_event_rate(np.array([12] + [0] * 99), 10.0)
    >>> [round(x, 2) for x in one_window["ci95"]]          # as if independent
    [0.62, 2.1]
    >>> [round(x, 2) for x in one_window["ci95_windows"]]  # about one event
    [0.03, 6.69]
    """
    counts = np.asarray(counts)
    if counts.ndim != 1 or counts.size == 0 or np.any(counts < 0):
        raise ValueError(
            f"counts must be a non-empty 1-d array of counts >= 0; got {counts!r}"
        )
    total = int(counts.sum())
    out = event_rate(total, hours)
    phi = 1.0
    if total > 0 and counts.size > 1:
        phi = max(1.0, float(counts.var(ddof=1) / counts.mean()))
    low, high = poisson_rate_interval(total / phi, hours / phi)
    return out | {
        "ci95_windows": [low, high],
        "dispersion": phi,
        "windows": int(counts.size),
        "windows_with_events": int(np.count_nonzero(counts)),
    }


def relative_gap(x: float, reference: float) -> float:
    """``|x - reference| / |reference|`` (0 or infinite for a zero reference).

    Examples
    --------
    >>> relative_gap(0.9, 1.0) < 0.11, relative_gap(0.0, 0.0), relative_gap(1.0, 0.0)
    (True, 0.0, inf)
    """
    if reference != 0:
        return abs(x - reference) / abs(reference)
    return 0.0 if x == 0 else float("inf")
