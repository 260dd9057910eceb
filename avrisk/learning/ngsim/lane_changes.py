"""Lane changes in lateral trajectories: detection, duration, lateral profile, rate.

One detector serves the NGSIM data and the simulator's traces, so that both
are measured alike. On a trajectory ``y`` (lateral position [m], any frame
whose lanes are the bands ``[k w, (k + 1) w)``, ``w`` the lane width):

1. smooth ``y`` (Gaussian, ``smoothing`` [s]; raw NGSIM positions jitter by
   decimetres) and take the lateral speed ``vy`` by central differences;
2. lane index ``floor(y_smooth / w)``; its runs of equal value;
3. a *lane change* is a boundary crossing into a lane the vehicle then stays
   in for at least ``min_stay`` [s]: a run shorter than that (a brief excursion
   over a marking, or the few frames of a lane crossed on the way to the next)
   does not settle the vehicle; a vehicle that settles ``n`` lanes away from
   the last lane it settled in made ``n`` changes, one per boundary crossed;
4. each change runs from the last frame before the crossing at which the
   lateral speed towards the new lane was at noise level (``noise_speed``) to
   the first such frame after it: its duration [s]; its *peak lateral speed*
   is the largest ``|vy|`` in between [m/s].

A crossing in the last ``min_stay`` of a trajectory cannot be confirmed and is
not counted; the exposure of a trajectory is therefore its duration less
``min_stay`` (:func:`exposure_seconds`), and a rate is changes over exposure.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0, 30, 0.1)
>>> y = 1.8 + 3.6 / (1 + np.exp(-(t - 15.0) / 0.8))   # one change to the left
>>> ev = detect_lane_changes(y, 0.1, lane_width=3.6, noise_speed=0.2)
>>> ev.direction.tolist(), round(float(ev.crossing_time[0]), 1)
([1], 15.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.ndimage import gaussian_filter1d

from avrisk.learning.ngsim.lateral import LATERAL_SMOOTHING
from avrisk.learning.ngsim.samples import FloatArray, IntArray

__all__ = [
    "MIN_STAY",
    "LaneChanges",
    "detect_lane_changes",
    "detect_in_episodes",
    "exposure_seconds",
    "lane_keeping_noise_speed",
    "lateral_speed",
    "poisson_rate_interval",
]

#: Time a vehicle must stay in a new lane for the crossing to count [s].
MIN_STAY = 2.0


@dataclass(frozen=True)
class LaneChanges:
    """Detected lane changes, one entry per change (arrays of shape (N,)).

    Attributes
    ----------
    track : ndarray of int64
        Index of the trajectory the change belongs to (0 for one trajectory).
    crossing : ndarray of int64
        Frame of the boundary crossing (first frame in the new lane).
    start, end : ndarray of int64
        First and last frame of the manoeuvre (lateral speed above noise).
    direction : ndarray of int64
        ``+1`` towards larger ``y``, ``-1`` towards smaller ``y``.
    crossing_time, duration : ndarray of float64
        Time of the crossing from the trajectory's start, and
        ``(end - start) dt`` [s].
    peak_lateral_speed : ndarray of float64
        Largest ``|vy|`` of the smoothed track over ``[start, end]`` [m/s].
    """

    track: IntArray
    crossing: IntArray
    start: IntArray
    end: IntArray
    direction: IntArray
    crossing_time: FloatArray  # s
    duration: FloatArray  # s
    peak_lateral_speed: FloatArray  # m/s

    def __len__(self) -> int:
        return len(self.track)

    @classmethod
    def concat(cls, parts: Sequence[LaneChanges]) -> LaneChanges:
        """The changes of several detections, in order."""
        names = cls.__dataclass_fields__
        if not parts:
            return cls(**{n: np.zeros(0, _dtype(n)) for n in names})
        return cls(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in names})


def _dtype(name: str) -> type:
    ints = {"track", "crossing", "start", "end", "direction"}
    return np.int64 if name in ints else np.float64


def lateral_speed(
    y: NDArray[Any], dt: float, smoothing: float = LATERAL_SMOOTHING
) -> tuple[FloatArray, FloatArray]:
    """Smoothed lateral position and its time derivative.

    Parameters
    ----------
    y : ndarray of shape (T,)
        Lateral position [m].
    dt : float
        Frame interval [s].
    smoothing : float, default=LATERAL_SMOOTHING
        Gaussian sigma [s]; 0 leaves ``y`` as it is.

    Returns
    -------
    y_smooth, vy : ndarray of shape (T,)
        [m] and [m/s] (0 for a single frame).
    """
    y = np.asarray(y, np.float64)
    ys = gaussian_filter1d(y, smoothing / dt, mode="nearest") if smoothing > 0 else y
    vy = np.gradient(ys, dt) if len(ys) > 1 else np.zeros_like(ys)
    return ys, vy


def _settled_changes(lane: IntArray, stay: int) -> list[tuple[int, int, int]]:
    """(crossing frame, direction, lanes) of every crossing into a settled lane."""
    change = np.flatnonzero(lane[1:] != lane[:-1]) + 1
    starts = np.r_[0, change]
    ends = np.r_[change, len(lane)]
    settled = lane[0]
    out = []
    for s, e in zip(starts[1:], ends[1:], strict=True):
        if lane[s] == settled or e - s < stay:
            continue
        step = 1 if lane[s] > settled else -1
        # One change per boundary: the last frame entering each lane on the way.
        for k in range(settled + step, lane[s] + step, step):
            entered = np.flatnonzero(lane[: s + 1] == k)
            first_in = entered[-1]
            while first_in > 0 and lane[first_in - 1] == k:
                first_in -= 1
            out.append((int(first_in), step, int(k)))
        settled = lane[s]
    return out


def detect_lane_changes(
    y: NDArray[Any],
    dt: float,
    *,
    lane_width: float,
    noise_speed: float,
    smoothing: float = LATERAL_SMOOTHING,
    min_stay: float = MIN_STAY,
    track: int = 0,
) -> LaneChanges:
    """Lane changes of one trajectory (see the module docstring).

    Parameters
    ----------
    y : ndarray of shape (T,)
        Lateral position [m]; lane ``k`` is ``[k w, (k + 1) w)``.
    dt : float
        Frame interval [s].
    lane_width : float
        ``w`` [m].
    noise_speed : float
        Lateral speed of lane keeping [m/s]: a manoeuvre lasts while the
        speed towards the new lane exceeds it.
    smoothing : float, default=LATERAL_SMOOTHING
        Gaussian sigma [s].
    min_stay : float, default=MIN_STAY
        [s].
    track : int, default=0
        Written to :attr:`LaneChanges.track`.

    Returns
    -------
    LaneChanges
    """
    ys, vy = lateral_speed(y, dt, smoothing)
    if len(ys) == 0:
        return LaneChanges.concat([])
    lane = np.floor(ys / lane_width).astype(np.int64)
    stay = max(1, round(min_stay / dt))
    rows = []
    for crossing, step, _ in _settled_changes(lane, stay):
        moving = step * vy > noise_speed
        start = crossing
        while start > 0 and moving[start - 1]:
            start -= 1
        end = crossing
        while end < len(ys) - 1 and moving[end + 1]:
            end += 1
        peak = float(np.abs(vy[start : end + 1]).max())
        rows.append((crossing, start, end, step, peak))
    if not rows:
        return LaneChanges.concat([])
    crossing, start, end, direction, peak = (
        np.array(c) for c in zip(*rows, strict=True)
    )
    return LaneChanges(
        track=np.full(len(rows), track, np.int64),
        crossing=crossing.astype(np.int64),
        start=start.astype(np.int64),
        end=end.astype(np.int64),
        direction=direction.astype(np.int64),
        crossing_time=crossing * dt,
        duration=(end - start) * dt,
        peak_lateral_speed=peak.astype(np.float64),
    )


def detect_in_episodes(
    y: NDArray[Any], starts: NDArray[Any], ends: NDArray[Any], dt: float, **kwargs: Any
) -> LaneChanges:
    """:func:`detect_lane_changes` on each episode ``y[starts[i]:ends[i]]``.

    ``track`` is the episode's index ``i``; other keywords as there.
    """
    return LaneChanges.concat(
        [
            detect_lane_changes(y[s:e], dt, track=i, **kwargs)
            for i, (s, e) in enumerate(zip(starts, ends, strict=True))
        ]
    )


def lane_keeping_noise_speed(
    y: NDArray[Any],
    starts: NDArray[Any],
    ends: NDArray[Any],
    dt: float,
    *,
    lane_width: float,
    smoothing: float = LATERAL_SMOOTHING,
    margin: float = 5.0,
    quantile: float = 0.95,
) -> float:
    """The lateral speed of lane keeping: a quantile of ``|vy|`` away from crossings.

    Frames within ``margin`` [s] of any boundary crossing of the smoothed track
    (settled or not) are left out; the ``quantile`` of the others' ``|vy|`` is
    the noise level of :func:`detect_lane_changes`.

    Parameters
    ----------
    y : ndarray of shape (N,)
        Lateral positions [m] of the episodes ``[starts[i], ends[i])``.
    starts, ends : ndarray of int64, shape (E,)
    dt, lane_width, smoothing
        As in :func:`detect_lane_changes`.
    margin : float, default=5.0
        [s].
    quantile : float, default=0.95

    Returns
    -------
    float
        [m/s].
    """
    keep = []
    pad = round(margin / dt)
    for s, e in zip(starts, ends, strict=True):
        ys, vy = lateral_speed(y[s:e], dt, smoothing)
        lane = np.floor(ys / lane_width)
        far = np.ones(len(ys), bool)
        for c in np.flatnonzero(lane[1:] != lane[:-1]) + 1:
            far[max(0, c - pad) : c + pad] = False
        keep.append(np.abs(vy[far]))
    return float(np.quantile(np.concatenate(keep), quantile))


def exposure_seconds(
    n_frames: NDArray[Any] | int, dt: float, min_stay: float = MIN_STAY
) -> FloatArray:
    """Time over which a trajectory of ``n_frames`` frames can show a change [s].

    Its duration ``(n_frames - 1) dt`` less ``min_stay`` (a crossing later
    than that cannot be confirmed), at least 0.
    """
    n = np.asarray(n_frames, np.float64)
    return np.maximum((n - 1.0) * dt - min_stay, 0.0)


def poisson_rate_interval(
    k: float, exposure: float, level: float = 0.95
) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson rate: ``k`` events in ``exposure``.

    Parameters
    ----------
    k : float
        Events, ``>= 0``: a count, or an effective count (not necessarily an
        integer) where events are overdispersed
        (:func:`avrisk.realism.metrics.clustered_event_rate`).
    exposure : float
        ``> 0`` (e.g. vehicle-hours: the rate is then per vehicle-hour).
    level : float, default=0.95

    Returns
    -------
    (low, high) : tuple of float
        ``low`` is 0 for ``k = 0``.

    Examples
    --------
    >>> low, high = poisson_rate_interval(0, 1.0)
    >>> low, round(high, 3)
    (0.0, 3.689)
    """
    if k < 0 or not exposure > 0 or not 0.0 < level < 1.0:
        raise ValueError(
            f"need k >= 0, exposure > 0, level in (0, 1); got {k}, {exposure}, {level}"
        )
    tail = (1.0 - level) / 2.0
    low = 0.0 if k == 0 else 0.5 * float(stats.chi2.ppf(tail, 2 * k))
    high = 0.5 * float(stats.chi2.ppf(1.0 - tail, 2 * k + 2))
    return low / exposure, high / exposure
