"""Lane changes of the US-101 vehicles: a held-out split, two small tables, statistics.

The US-101 file (``us101_vehicle_subset.csv.gz``, not shipped; see the data
folder's ``SOURCE.md``) holds 370 single vehicles with their lateral position
and no lane ids. :func:`lane_change_tables` turns it into two small tables,
shipped in ``avrisk/data/ngsim/`` (:data:`VEHICLES_FILE`, :data:`EVENTS_FILE`)
and read by :func:`load_lane_change_tables`:

* *vehicles*: one row per vehicle with its split, frames, exposure [s], mean
  speed [m/s] and number of lane changes;
* *events*: one row per lane change (:mod:`avrisk.learning.ngsim.lane_changes`),
  with its vehicle, split, crossing frame, direction (avrisk frame: ``+1``
  left), duration [s], peak lateral speed [m/s] and speed [m/s].

The split is drawn first, from the vehicle ids alone (:func:`us101_split`: a
third held out at random with the fixed seed :data:`SPLIT_SEED`). The one
quantity the detector learns from data, the lateral speed of lane keeping
(its noise level), is measured on the training vehicles only and then applied
to all. Lanes are the 12 ft bands of the NGSIM frame
(:data:`~avrisk.learning.ngsim.samples.US101_LANE_WIDTH`).

:func:`lane_change_statistics` gives a split's rate per vehicle-hour with its
exact Poisson interval, and the quantiles of duration and peak lateral speed;
the training split's rate is the hazard of the learned drivers' lane-change
layer (:mod:`avrisk.agents.drivers.lane_change`), the held-out split is what
the simulator is checked against (``avrisk realism``, part B:
:mod:`avrisk.realism.lane_changes`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from avrisk.learning.ngsim.files import default_ngsim_dir
from avrisk.learning.ngsim.lane_changes import (
    MIN_STAY,
    detect_in_episodes,
    exposure_seconds,
    lane_keeping_noise_speed,
    poisson_rate_interval,
)
from avrisk.learning.ngsim.lateral import LATERAL_SMOOTHING
from avrisk.learning.ngsim.samples import (
    US101_LANE_WIDTH,
    VehicleTrajectories,
    episode_bounds,
)

__all__ = [
    "DT",
    "EVENTS_FILE",
    "HELD_OUT_FRACTION",
    "SPLIT_SEED",
    "VEHICLES_FILE",
    "LaneChangeStatistics",
    "LaneChangeTables",
    "lane_change_statistics",
    "lane_change_tables",
    "load_lane_change_tables",
    "split_statistics",
    "us101_split",
    "write_lane_change_tables",
]

#: NGSIM frame interval [s].
DT = 0.1
#: Seed of the held-out draw (fixed: the shipped tables hold its split).
SPLIT_SEED = 21
#: Share of the vehicles held out for evaluation.
HELD_OUT_FRACTION = 1.0 / 3.0
#: Per-vehicle table shipped in the package's NGSIM folder.
VEHICLES_FILE = "us101_lane_change_vehicles.parquet"
#: Per-lane-change table shipped beside it.
EVENTS_FILE = "us101_lane_changes.parquet"
#: Key of the tables' schema metadata (JSON: how they were made).
METADATA_KEY = b"avrisk.lane_changes"
#: Version of the tables' layout.
FORMAT_VERSION = 1


def us101_split(vehicle_ids: np.ndarray, seed: int = SPLIT_SEED) -> np.ndarray:
    """``"train"`` or ``"test"`` for each of the sorted unique ``vehicle_ids``.

    ``round(n / 3)`` vehicles, drawn by a permutation of the sorted ids with
    ``numpy.random.default_rng(seed)``, are ``"test"``.

    Parameters
    ----------
    vehicle_ids : ndarray of int64, shape (N,)
        Any order, repeats allowed.
    seed : int, default=SPLIT_SEED

    Returns
    -------
    ndarray of str, shape (V,)
        Per vehicle of ``np.unique(vehicle_ids)``.

    Examples
    --------
    >>> us101_split(np.array([5, 3, 3, 9])).tolist()
    ['train', 'test', 'train']
    """
    ids = np.unique(vehicle_ids)
    held = np.random.default_rng(seed).permutation(len(ids))[
        : round(len(ids) * HELD_OUT_FRACTION)
    ]
    split = np.full(len(ids), "train", dtype="<U5")
    split[held] = "test"
    return split


@dataclass(frozen=True)
class LaneChangeTables:
    """The two US-101 lane-change tables (see the module docstring).

    Attributes
    ----------
    vehicles : pyarrow.Table
        ``vehicle_id, split, n_frames, exposure_s, mean_speed, lane_changes``.
    events : pyarrow.Table
        ``vehicle_id, split, crossing_frame, direction, duration_s,
        peak_lateral_speed, speed``.
    noise_speed : float
        Lateral speed of lane keeping on the training vehicles [m/s].
    """

    vehicles: pa.Table
    events: pa.Table
    noise_speed: float

    def equals(self, other: LaneChangeTables) -> bool:
        """Whether both tables and the noise levels agree.

        Columns of integers and strings must be identical; floating-point
        columns and the noise level agree to within a relative 1e-12, since
        numpy's vectorised arithmetic rounds differently on CPUs with and
        without AVX-512 (in the last bits of the peak lateral speeds).
        """
        return (
            _tables_agree(self.vehicles, other.vehicles)
            and _tables_agree(self.events, other.events)
            and math.isclose(self.noise_speed, other.noise_speed, rel_tol=1e-12)
        )


def _tables_agree(a: pa.Table, b: pa.Table) -> bool:
    """Same schema, integer and string columns equal, floats within 1e-12."""
    if a.schema != b.schema or a.num_rows != b.num_rows:
        return False
    for name in a.column_names:
        x, y = a[name], b[name]
        if pa.types.is_floating(x.type):
            if not np.allclose(x.to_numpy(), y.to_numpy(), rtol=1e-12, atol=0.0):
                return False
        elif not x.equals(y):
            return False
    return True


def _metadata(noise_speed: float) -> dict[bytes, bytes]:
    info = {
        "format_version": FORMAT_VERSION,
        "split_seed": SPLIT_SEED,
        "held_out_fraction": HELD_OUT_FRACTION,
        "lane_width_m": US101_LANE_WIDTH,
        "smoothing_s": LATERAL_SMOOTHING,
        "min_stay_s": MIN_STAY,
        "noise_speed_m_s": noise_speed,
    }
    return {METADATA_KEY: json.dumps(info, sort_keys=True).encode()}


def lane_change_tables(us: VehicleTrajectories) -> LaneChangeTables:
    """The lane-change tables of the US-101 trajectories (reproduces the shipped ones).

    Parameters
    ----------
    us : VehicleTrajectories
        :func:`avrisk.learning.ngsim.loaders.load_us101` of the original file.

    Returns
    -------
    LaneChangeTables
    """
    starts, ends = episode_bounds(us.vehicle_id)
    ids = us.vehicle_id[starts]
    split = us101_split(ids)
    y = -us.lateral  # avrisk frame: to the left; lanes stay the 12 ft bands
    train = split == "train"
    noise = lane_keeping_noise_speed(
        y, starts[train], ends[train], DT, lane_width=US101_LANE_WIDTH
    )
    ev = detect_in_episodes(
        y, starts, ends, DT, lane_width=US101_LANE_WIDTH, noise_speed=noise
    )
    row = starts[ev.track] + ev.crossing
    meta = _metadata(noise)
    vehicles = pa.table(
        {
            "vehicle_id": ids,
            "split": split,
            "n_frames": ends - starts,
            "exposure_s": exposure_seconds(ends - starts, DT),
            "mean_speed": np.array(
                [us.speed[s:e].mean() for s, e in zip(starts, ends, strict=True)]
            ),
            "lane_changes": np.bincount(ev.track, minlength=len(ids)).astype(np.int64),
        }
    ).replace_schema_metadata(meta)
    events = pa.table(
        {
            "vehicle_id": ids[ev.track],
            "split": split[ev.track],
            "crossing_frame": us.frame[row],
            "direction": ev.direction,
            "duration_s": ev.duration,
            "peak_lateral_speed": ev.peak_lateral_speed,
            "speed": us.speed[row],
        }
    ).replace_schema_metadata(meta)
    return LaneChangeTables(vehicles=vehicles, events=events, noise_speed=noise)


def write_lane_change_tables(tables: LaneChangeTables, folder: str | Path) -> None:
    """Write :data:`VEHICLES_FILE` and :data:`EVENTS_FILE` to ``folder``."""
    folder = Path(folder)
    for table, name in ((tables.vehicles, VEHICLES_FILE), (tables.events, EVENTS_FILE)):
        pq.write_table(table, folder / name, compression="zstd", compression_level=19)


def load_lane_change_tables(folder: str | Path | None = None) -> LaneChangeTables:
    """Read the lane-change tables (default: those shipped with the package).

    Parameters
    ----------
    folder : str or Path, optional
        Default :func:`~avrisk.learning.ngsim.files.default_ngsim_dir`.

    Returns
    -------
    LaneChangeTables

    Raises
    ------
    ValueError
        If the files are of another format version.
    """
    folder = default_ngsim_dir() if folder is None else Path(folder)
    vehicles = pq.read_table(folder / VEHICLES_FILE)
    events = pq.read_table(folder / EVENTS_FILE)
    info = json.loads((vehicles.schema.metadata or {})[METADATA_KEY])
    if info["format_version"] != FORMAT_VERSION:
        raise ValueError(
            f"{folder / VEHICLES_FILE} has format version {info['format_version']}; "
            f"this avrisk reads {FORMAT_VERSION} (rebuild it with "
            "scripts/pack_us101_lane_changes.py)"
        )
    return LaneChangeTables(vehicles, events, float(info["noise_speed_m_s"]))


@dataclass(frozen=True)
class LaneChangeStatistics:
    """Lane changes of one group of vehicles.

    Attributes
    ----------
    vehicles : int
    hours : float
        Exposure [vehicle-h].
    changes : int
    rate : float
        ``changes / hours`` [1/vehicle-h].
    rate_low, rate_high : float
        Exact 95% Poisson interval of the rate [1/vehicle-h].
    left_fraction : float
        Share of changes to the left [-].
    duration_q10, duration_q50, duration_q90 : float
        Quantiles of the duration [s] (NaN without changes).
    peak_q10, peak_q50, peak_q90 : float
        Quantiles of the peak lateral speed [m/s].
    """

    vehicles: int
    hours: float
    changes: int
    rate: float
    rate_low: float
    rate_high: float
    left_fraction: float
    duration_q10: float
    duration_q50: float
    duration_q90: float
    peak_q10: float
    peak_q50: float
    peak_q90: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return asdict(self)


def lane_change_statistics(
    n_vehicles: int,
    exposure_s: float,
    direction: np.ndarray,
    duration: np.ndarray,
    peak_lateral_speed: np.ndarray,
) -> LaneChangeStatistics:
    """Rate with its interval, direction and profile quantiles of a group.

    Parameters
    ----------
    n_vehicles : int
    exposure_s : float
        Total exposure [vehicle-s]
        (:func:`~avrisk.learning.ngsim.lane_changes.exposure_seconds`).
    direction, duration, peak_lateral_speed : ndarray of shape (N,)
        Of the group's changes (``+1`` left; [s]; [m/s]).

    Returns
    -------
    LaneChangeStatistics
    """
    hours = float(exposure_s) / 3600.0
    k = len(direction)
    low, high = poisson_rate_interval(k, hours)

    def q(x: np.ndarray) -> list[float]:
        if len(x) == 0:
            return [float("nan")] * 3
        return [float(v) for v in np.quantile(x, [0.1, 0.5, 0.9])]

    d, p = q(np.asarray(duration)), q(np.asarray(peak_lateral_speed))
    return LaneChangeStatistics(
        vehicles=int(n_vehicles),
        hours=hours,
        changes=k,
        rate=k / hours,
        rate_low=low,
        rate_high=high,
        left_fraction=float(np.mean(np.asarray(direction) > 0)) if k else float("nan"),
        duration_q10=d[0],
        duration_q50=d[1],
        duration_q90=d[2],
        peak_q10=p[0],
        peak_q50=p[1],
        peak_q90=p[2],
    )


def split_statistics(tables: LaneChangeTables, split: str) -> LaneChangeStatistics:
    """:func:`lane_change_statistics` of the ``"train"`` or ``"test"`` vehicles."""
    if split not in ("train", "test"):
        raise ValueError(f"split must be 'train' or 'test'; got {split!r}")
    veh = tables.vehicles.filter(pc.equal(tables.vehicles["split"], split))
    ev = tables.events.filter(pc.equal(tables.events["split"], split))
    return lane_change_statistics(
        veh.num_rows,
        float(np.sum(veh["exposure_s"].to_numpy())),
        ev["direction"].to_numpy(),
        ev["duration_s"].to_numpy(),
        ev["peak_lateral_speed"].to_numpy(),
    )
