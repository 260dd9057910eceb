"""Lane keeping in the NGSIM lateral pairs: lane centres, offsets, headings, steering.

The lateral I-80 file gives each follower's lateral position. Measured from
its lane's centre line (:class:`LaneCentres`, which follows the lanes' drift
along the section) and smoothed over about a second, it gives the follower's
lateral offset and heading, and the steering that turns that heading
(:func:`lateral_tracks`). Steering [rad] is the front-wheel angle of the
simulator's kinematic bicycle (:mod:`avrisk.sim.dynamics`) that turns the
heading from ``t`` to ``t+1`` (:func:`steer_from_heading`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from avrisk.learning.ngsim.samples import LateralPairs, episode_bounds

__all__ = [
    "LATERAL_SMOOTHING",
    "WHEELBASE_FRACTION",
    "LaneCentres",
    "lateral_tracks",
    "steer_from_heading",
]

#: Smoothing of lateral tracks before differentiating (Gaussian sigma) [s].
LATERAL_SMOOTHING = 1.0
#: Wheelbase over length, as in the simulator's default bicycle [-].
WHEELBASE_FRACTION = 0.6


def steer_from_heading(
    heading: NDArray[Any], speed: NDArray[Any], length: NDArray[Any], dt: float
) -> NDArray[np.float64]:
    """Front-wheel angle that turns ``heading[t]`` into ``heading[t+1]``.

    Inverse of the simulator's kinematic bicycle (:mod:`avrisk.sim.dynamics`):
    ``dpsi = v sin(beta) dt / l_r`` with ``l_r = 0.3 length`` and
    ``tan(steer) = 2 tan(beta)``.

    Parameters
    ----------
    heading : ndarray of shape (T,)
        [rad].
    speed : ndarray of shape (T,)
        [m/s].
    length : ndarray of shape (T,) or float
        [m].
    dt : float
        [s].

    Returns
    -------
    ndarray of shape (T,)
        [rad]; the last entry repeats the one before (no next heading).

    Examples
    --------
    >>> import numpy as np
    >>> psi = np.array([0.0, 0.01])   # 0.01 rad in 0.1 s at 10 m/s, l = 4 m
    >>> round(float(steer_from_heading(psi, np.full(2, 10.0), 4.0, 0.1)[0]), 4)
    0.024
    """
    if len(heading) < 2:
        return np.zeros(len(heading))
    dpsi = np.diff(heading)
    v = np.maximum(np.asarray(speed, np.float64)[:-1], 0.5)
    l_r = 0.5 * WHEELBASE_FRACTION * np.broadcast_to(length, heading.shape)[:-1]
    sin_beta = np.clip(dpsi * l_r / (v * dt), -0.99, 0.99)
    tan_beta = sin_beta / np.sqrt(1.0 - sin_beta**2)
    steer = np.arctan(2.0 * tan_beta)
    return np.r_[steer, steer[-1]]


@dataclass(frozen=True)
class LaneCentres:
    """Centre line of each NGSIM lane as a function of the position along the road.

    The lanes of the lateral I-80 file are not straight in its frame: their
    median lateral position wanders by about 0.6 m over the 500 m section.
    Offsets measured from a constant centre would carry that as a systematic
    heading and steering; offsets from this profile do not.

    Attributes
    ----------
    x : ndarray of shape (K,)
        Bin centres along the road [m].
    lanes : tuple of int
        NGSIM lanes, in the order of the rows of ``centre``.
    centre : ndarray of shape (L, K)
        Median lateral position (``Local_X``) of each lane in each bin [m].
    """

    x: NDArray[np.float64]
    lanes: tuple[int, ...]
    centre: NDArray[np.float64]

    @classmethod
    def fit(cls, lateral: LateralPairs, bin_width: float = 25.0) -> LaneCentres:
        """Medians per lane and ``bin_width`` [m] bin (empty bins interpolated)."""
        edges = np.arange(
            np.floor(lateral.x.min()), lateral.x.max() + bin_width, bin_width
        )
        mids = 0.5 * (edges[1:] + edges[:-1])
        lanes = tuple(int(k) for k in np.unique(lateral.lane))
        rows = []
        for k in lanes:
            m = lateral.lane == k
            idx = np.digitize(lateral.x[m], edges) - 1
            med = np.array(
                [
                    np.median(lateral.lateral[m][idx == b])
                    if (idx == b).any()
                    else np.nan
                    for b in range(len(mids))
                ]
            )
            ok = ~np.isnan(med)
            rows.append(np.interp(mids, mids[ok], med[ok]))
        return cls(x=mids, lanes=lanes, centre=np.array(rows))

    def __call__(self, lane: NDArray[Any], x: NDArray[Any]) -> NDArray[np.float64]:
        """Centre line [m] of ``lane`` at ``x``, arrays of shape (N,)."""
        out = np.empty(len(lane))
        for row, k in enumerate(self.lanes):
            m = lane == k
            out[m] = np.interp(x[m], self.x, self.centre[row])
        unknown = ~np.isin(lane, self.lanes)
        if unknown.any():
            raise ValueError(f"no centre line for lanes {np.unique(lane[unknown])}")
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the profile per lane)."""
        return {
            "x_m": self.x.round(2).tolist(),
            **{
                str(k): self.centre[i].round(3).tolist()
                for i, k in enumerate(self.lanes)
            },
        }


def lateral_tracks(
    lateral: LateralPairs, centres: LaneCentres, dt: float = 0.1
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Smoothed lateral offset, heading offset and steering of every row.

    Parameters
    ----------
    lateral : LateralPairs
    centres : LaneCentres
        Lane centre lines (:meth:`LaneCentres.fit`).
    dt : float, default=0.1
        [s].

    Returns
    -------
    offset : ndarray of shape (N,)
        Lateral offset from the lane centre [m], positive to the left.
    heading : ndarray of shape (N,)
        Heading relative to the lane [rad], counter-clockwise.
    steer : ndarray of shape (N,)
        Front-wheel angle [rad] (:func:`steer_from_heading`).
    """
    y = -(lateral.lateral - centres(lateral.lane, lateral.x))  # avrisk: to the left
    offset = np.empty_like(y)
    heading = np.empty_like(y)
    steer = np.empty_like(y)
    sigma = LATERAL_SMOOTHING / dt
    starts, ends = episode_bounds(lateral.pair_id)
    for s, e in zip(starts, ends, strict=True):
        ys = gaussian_filter1d(y[s:e], sigma, mode="nearest")
        v = lateral.speed[s:e]
        vy = np.gradient(ys, dt) if e - s > 1 else np.zeros(e - s)
        psi = np.arctan2(vy, np.maximum(v, 0.5))
        offset[s:e] = ys
        heading[s:e] = psi
        steer[s:e] = steer_from_heading(psi, v, lateral.length[s:e], dt)
    return offset, heading, steer
