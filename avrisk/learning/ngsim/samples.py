"""The NGSIM data sets in memory: one frozen dataclass of SI columns per data set.

:class:`CarFollowingPairs` (I-80 leader-follower pairs, longitudinal only),
:class:`LateralPairs` (I-80 16:00-16:15 pairs with lateral positions) and
:class:`VehicleTrajectories` (US-101 single vehicles) hold equal-length numpy
columns, one row per 0.1 s sample, the rows of one episode contiguous
(:func:`episode_bounds`). The loaders of :mod:`avrisk.learning.ngsim.loaders` fill them.

NGSIM frame: ``Local_Y`` runs along the road in the direction of travel and
marks the *front* centre of the vehicle; ``Local_X`` is lateral, from the
left-most edge of the section, increasing to the **right**; lane 1 is the
left-most lane. (avrisk's road frame has ``y`` increasing to the left and lane
0 on the right; :mod:`avrisk.learning.imitation.ngsim_demonstrations` converts.)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Self

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DEFAULT_WIDTH",
    "FT",
    "I80_LANE_WIDTH",
    "I80_N_LANES",
    "US101_LANE_WIDTH",
    "CarFollowingPairs",
    "FloatArray",
    "IntArray",
    "LateralPairs",
    "VehicleTrajectories",
    "episode_bounds",
]

#: One international foot [m].
FT = 0.3048
#: Main-line lanes of I-80 in the study area (lane 7 is the on-ramp).
I80_N_LANES = 6
#: Nominal lane width of I-80 and US-101 (12 ft) [m].
I80_LANE_WIDTH = US101_LANE_WIDTH = 12 * FT
#: Width of a vehicle whose width the data do not give [m].
DEFAULT_WIDTH = 1.9

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]


class _Columns:
    """Shared helpers of the column dataclasses (all fields: arrays of one length)."""

    def __len__(self) -> int:
        return len(getattr(self, dataclasses.fields(self)[0].name))  # type: ignore[arg-type]

    def _check(self) -> None:
        lengths = {f.name: len(getattr(self, f.name)) for f in dataclasses.fields(self)}  # type: ignore[arg-type]
        if len(set(lengths.values())) > 1:
            raise ValueError(
                f"{type(self).__name__}: columns differ in length {lengths}"
            )

    def take(self, index: Any) -> Self:
        """Rows ``index`` (a mask, slice or integer array) of every column."""
        return dataclasses.replace(
            self,  # type: ignore[type-var]
            **{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)},  # type: ignore[arg-type]
        )


@dataclass(frozen=True)
class CarFollowingPairs(_Columns):
    """I-80 leader-follower pairs (``i80_cf_pairs.csv.gz``), in SI units.

    Every column is an array of shape (N,), rows sorted by ``pair_id`` then
    ``t``. Positions mark the front bumper (NGSIM ``Local_Y``).

    Attributes
    ----------
    pair_id : ndarray of int64
        Pair (episode) id, unique in the file.
    period : ndarray of str
        Recording period, e.g. ``"0400pm-0415pm"``.
    follower_id, leader_id : ndarray of int64
        NGSIM ``Vehicle_ID`` within the period.
    lane : ndarray of int64
        NGSIM lane (1 = left-most); -1 where the source does not say.
    split : ndarray of str
        ``"train"`` or ``"test"``, from the source repository.
    in_manifest : ndarray of bool
        The pair is listed in the source's curated manifest.
    t : ndarray of float64
        Time from the start of the period [s].
    x_follower, x_leader : ndarray of float64
        Position along the road [m] (file: ft).
    v_follower, v_leader : ndarray of float64
        Speed [m/s] (file: ft/s).
    a_follower, a_leader : ndarray of float64
        Acceleration [m/s^2] (file: ft/s^2).
    leader_length : ndarray of float64
        Leader length [m] (file: ft).
    gap : ndarray of float64
        Bumper-to-bumper gap ``x_leader - x_follower - leader_length`` [m]
        (the file's ``spacing``, ft).
    dv : ndarray of float64
        Approach rate ``v_follower - v_leader`` [m/s] (file: ft/s).
    """

    pair_id: IntArray
    period: NDArray[np.str_]
    follower_id: IntArray
    leader_id: IntArray
    lane: IntArray
    split: NDArray[np.str_]
    in_manifest: NDArray[np.bool_]
    t: FloatArray  # s
    x_follower: FloatArray  # m
    v_follower: FloatArray  # m/s
    a_follower: FloatArray  # m/s^2
    x_leader: FloatArray  # m
    v_leader: FloatArray  # m/s
    a_leader: FloatArray  # m/s^2
    leader_length: FloatArray  # m
    gap: FloatArray  # m
    dv: FloatArray  # m/s

    def __post_init__(self) -> None:
        self._check()


@dataclass(frozen=True)
class LateralPairs(_Columns):
    """I-80 16:00-16:15 pairs with lateral positions (EMD parquet), SI units.

    Every column is an array of shape (N,), rows sorted by ``pair_id`` then
    ``t``; the follower's columns are unprefixed.

    Attributes
    ----------
    pair_id : ndarray of str
        ``"<follower>-<leader>"``.
    follower_id, leader_id : ndarray of int64
        NGSIM ``Vehicle_ID`` (16:00-16:15).
    frame : ndarray of int64
        NGSIM frame (0.1 s).
    t : ndarray of float64
        Time from the start of the pair [s].
    lateral : ndarray of float64
        ``Local_X``: front centre from the left edge of the section, to the
        right [m].
    x : ndarray of float64
        ``Local_Y``: front centre along the road [m].
    length, width : ndarray of float64
        Follower size [m].
    vehicle_class : ndarray of int64
        1 motorcycle, 2 car, 3 truck.
    speed : ndarray of float64
        [m/s].
    accel : ndarray of float64
        [m/s^2].
    lane : ndarray of int64
        NGSIM lane (1 = left-most).
    space_headway : ndarray of float64
        Front-to-front distance to the leader [m].
    time_headway : ndarray of float64
        [s].
    leader_x : ndarray of float64
        Leader's ``Local_Y`` [m].
    leader_length, leader_width : ndarray of float64
        [m].
    leader_class : ndarray of int64
    leader_speed : ndarray of float64
        [m/s].
    leader_accel : ndarray of float64
        [m/s^2].
    """

    pair_id: NDArray[np.str_]
    follower_id: IntArray
    leader_id: IntArray
    frame: IntArray
    t: FloatArray  # s
    lateral: FloatArray  # m
    x: FloatArray  # m
    length: FloatArray  # m
    width: FloatArray  # m
    vehicle_class: IntArray
    speed: FloatArray  # m/s
    accel: FloatArray  # m/s^2
    lane: IntArray
    space_headway: FloatArray  # m
    time_headway: FloatArray  # s
    leader_x: FloatArray  # m
    leader_length: FloatArray  # m
    leader_width: FloatArray  # m
    leader_class: IntArray
    leader_speed: FloatArray  # m/s
    leader_accel: FloatArray  # m/s^2

    def __post_init__(self) -> None:
        self._check()

    @property
    def gap(self) -> FloatArray:
        """Bumper-to-bumper gap to the leader [m], shape (N,)."""
        return self.space_headway - self.leader_length


@dataclass(frozen=True)
class VehicleTrajectories(_Columns):
    """US-101 single-vehicle trajectories (``us101_vehicle_subset.csv.gz``), SI.

    Every column is an array of shape (N,), rows sorted by ``vehicle_id`` then
    ``frame``. These are NGSIM's raw (unsmoothed) trajectories.

    Attributes
    ----------
    vehicle_id : ndarray of int64
    frame : ndarray of int64
        NGSIM frame (0.1 s).
    t : ndarray of float64
        ``Global_Time`` [s] since the Unix epoch (file: ms).
    lateral : ndarray of float64
        ``Local_X`` [m], to the right from the left edge.
    x : ndarray of float64
        ``Local_Y`` [m], front centre along the road.
    speed : ndarray of float64
        [m/s].
    accel : ndarray of float64
        [m/s^2] (NGSIM clips it at about +-3.45).
    space_headway : ndarray of float64
        Front-to-front distance to the leader [m]; NaN when there is none
        (file: 0).
    time_headway : ndarray of float64
        [s]; NaN when there is no leader (file: 9999.99).

    Notes
    -----
    The file's ``H_v_Vel(m)`` and ``H_v_Acc(m)`` columns are undocumented by
    their author and are not loaded.
    """

    vehicle_id: IntArray
    frame: IntArray
    t: FloatArray  # s
    lateral: FloatArray  # m
    x: FloatArray  # m
    speed: FloatArray  # m/s
    accel: FloatArray  # m/s^2
    space_headway: FloatArray  # m
    time_headway: FloatArray  # s

    def __post_init__(self) -> None:
        self._check()

    @property
    def lane(self) -> IntArray:
        """Lane from the lateral position, 1 = left-most (12 ft lanes), shape (N,)."""
        return np.floor(self.lateral / US101_LANE_WIDTH).astype(np.int64) + 1


def episode_bounds(keys: Sequence[Any] | NDArray[Any]) -> tuple[IntArray, IntArray]:
    """Start and end (exclusive) rows of the runs of equal consecutive keys.

    Parameters
    ----------
    keys : array_like of shape (N,)
        Episode key per row (rows of one episode contiguous).

    Returns
    -------
    starts, ends : ndarray of int64, shape (E,)

    Examples
    --------
    >>> starts, ends = episode_bounds([5, 5, 7, 7, 7, 2])
    >>> starts.tolist(), ends.tolist()
    ([0, 2, 5], [2, 5, 6])
    """
    k = np.asarray(keys)
    if k.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    change = np.flatnonzero(k[1:] != k[:-1]) + 1
    starts = np.r_[0, change].astype(np.int64)
    ends = np.r_[change, k.size].astype(np.int64)
    return starts, ends
