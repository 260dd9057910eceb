"""Loaders for the NGSIM samples the project uses, in SI units.

Three data sets (provenance in the data folder's ``SOURCE.md``), each read
into a frozen dataclass of :mod:`avrisk.learning.ngsim.samples`, one row per
0.1 s sample:

* :func:`load_i80_pairs` -- I-80 leader-follower car-following pairs
  (``i80_cf_pairs.csv.gz``). **The file is in feet**: positions [ft],
  speeds [ft/s] and accelerations [ft/s^2] are converted to m, m/s, m/s^2
  (``FT = 0.3048`` m exactly). Longitudinal only: no lateral position.
* :func:`load_i80_lateral` -- I-80 16:00-16:15 car-following pairs with
  lateral positions (``i80_0400_0415_emd_cf_pairs.parquet``); already SI.
* :func:`load_us101` -- US-101 single-vehicle trajectories with lateral
  positions (``us101_vehicle_subset.csv.gz``); already SI. The vehicles around
  them are not in the file.

The I-80 loaders read the original files or the packed ones shipped with the
package (:mod:`avrisk.learning.ngsim.files`, :mod:`avrisk.learning.ngsim.packed`)
and return the same arrays, bit for bit. :func:`lateral_pair_split` splits the
lateral pairs into train and test as the car-following pairs are split.

One I-80 period (17:15-17:30) is held back by the project for independent
evaluation and is not in these files.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from numpy.typing import NDArray

from avrisk.learning.ngsim.files import I80_LATERAL, I80_PAIRS, US101_FILE, ngsim_file
from avrisk.learning.ngsim.packed import i80_derived_columns, read_column
from avrisk.learning.ngsim.samples import (
    FT,
    CarFollowingPairs,
    LateralPairs,
    VehicleTrajectories,
)

__all__ = [
    "I80_FEET_COLUMNS",
    "I80_LATERAL_COLUMNS",
    "I80_PAIRS_COLUMNS",
    "LATERAL_PERIOD",
    "lateral_pair_split",
    "load_i80_lateral",
    "load_i80_pairs",
    "load_us101",
    "periods_of",
    "read_i80_pairs_table",
]

#: The recording period of the lateral file, as the pairs file names periods.
LATERAL_PERIOD = "0400pm-0415pm"

#: Columns of the I-80 pairs file that :func:`load_i80_pairs` reads, besides
#: the ones in feet.
I80_PAIRS_COLUMNS = (
    "pair_id", "period", "follower_id", "leader_id", "lane_id", "split",
    "in_manifest", "t",
)  # fmt: skip
#: Columns of the I-80 pairs file in feet, ft/s or ft/s^2, apart from those of
#: :func:`~avrisk.learning.ngsim.packed.i80_derived_columns`.
I80_FEET_COLUMNS = (
    "x_follower", "v_follower", "a_follower", "x_leader", "v_leader", "a_leader",
    "leader_length",
)  # fmt: skip
#: Columns of the lateral pairs file and the
#: :class:`~avrisk.learning.ngsim.samples.LateralPairs` fields they fill (besides
#: ``pair_id``).
I80_LATERAL_COLUMNS = {
    "vehicle_id": "follower_id", "preceding": "leader_id", "frame_id": "frame",
    "time": "t", "local_x": "lateral", "local_y": "x", "v_length": "length",
    "v_width": "width", "v_class": "vehicle_class", "v_vel": "speed",
    "v_acc": "accel", "lane_id": "lane", "space_headway": "space_headway",
    "time_headway": "time_headway", "preceding_local_y": "leader_x",
    "preceding_length": "leader_length", "preceding_width": "leader_width",
    "preceding_class": "leader_class", "preceding_vel": "leader_speed",
    "preceding_acc": "leader_accel",
}  # fmt: skip


def _require(table: pa.Table, names: Sequence[str], path: Path) -> None:
    missing = [n for n in names if n not in table.column_names]
    if missing:
        raise ValueError(f"{path} lacks the columns {missing}; see SOURCE.md")


def read_i80_pairs_table(path: str | Path) -> pa.Table:
    """The I-80 pairs file as stored (units of the file).

    Parameters
    ----------
    path : str or Path
        The packed ``.parquet`` file, or the original ``.csv`` or ``.csv.gz``.

    Returns
    -------
    pyarrow.Table
    """
    path = Path(path)
    if path.suffix == ".parquet":
        return pq.read_table(path)
    types = {"lane_id": pa.float64(), "period": pa.string(), "split": pa.string()}
    return pa_csv.read_csv(
        path, convert_options=pa_csv.ConvertOptions(column_types=types)
    )


def load_i80_pairs(path: str | Path | None = None) -> CarFollowingPairs:
    """Read the I-80 car-following pairs, converting feet to metres.

    Parameters
    ----------
    path : str or Path, optional
        The original ``.csv`` or ``.csv.gz`` file or the packed ``.parquet``;
        default the :data:`~avrisk.learning.ngsim.files.I80_PAIRS` file in
        :func:`~avrisk.learning.ngsim.files.ngsim_dir`.

    Returns
    -------
    CarFollowingPairs
        Sorted by pair and time.
    """
    path = Path(path) if path is not None else ngsim_file(I80_PAIRS)
    table = read_i80_pairs_table(path)
    _require(table, [*I80_PAIRS_COLUMNS, *I80_FEET_COLUMNS], path)
    lane = read_column(table, "lane_id", np.float64)
    order = np.lexsort(
        (read_column(table, "t", np.float64), read_column(table, "pair_id", np.int64))
    )
    feet = {
        name: read_column(table, name, np.float64)[order] for name in I80_FEET_COLUMNS
    }
    for name, values in i80_derived_columns(feet).items():
        in_file = name in table.column_names
        feet[name] = read_column(table, name, np.float64)[order] if in_file else values
    return CarFollowingPairs(
        pair_id=read_column(table, "pair_id", np.int64)[order],
        period=read_column(table, "period", str)[order],
        follower_id=read_column(table, "follower_id", np.int64)[order],
        leader_id=read_column(table, "leader_id", np.int64)[order],
        lane=np.where(np.isnan(lane), -1, np.nan_to_num(lane)).astype(np.int64)[order],
        split=read_column(table, "split", str)[order],
        in_manifest=read_column(table, "in_manifest", np.int64)[order] != 0,
        t=read_column(table, "t", np.float64)[order],
        x_follower=feet["x_follower"] * FT,
        v_follower=feet["v_follower"] * FT,
        a_follower=feet["a_follower"] * FT,
        x_leader=feet["x_leader"] * FT,
        v_leader=feet["v_leader"] * FT,
        a_leader=feet["a_leader"] * FT,
        leader_length=feet["leader_length"] * FT,
        gap=feet["spacing"] * FT,
        dv=feet["dv"] * FT,
    )


def load_i80_lateral(path: str | Path | None = None) -> LateralPairs:
    """Read the I-80 16:00-16:15 pairs with lateral positions (already SI).

    Parameters
    ----------
    path : str or Path, optional
        The original or the packed ``.parquet`` file (same column names);
        default the :data:`~avrisk.learning.ngsim.files.I80_LATERAL` file in
        :func:`~avrisk.learning.ngsim.files.ngsim_dir`.

    Returns
    -------
    LateralPairs
        Sorted by pair and time.
    """
    path = Path(path) if path is not None else ngsim_file(I80_LATERAL)
    table = pq.read_table(path)
    names = I80_LATERAL_COLUMNS
    _require(table, ["pair_id", *names], path)
    ints = {
        "follower_id",
        "leader_id",
        "frame",
        "vehicle_class",
        "lane",
        "leader_class",
    }
    cols: dict[str, NDArray[Any]] = {"pair_id": read_column(table, "pair_id", str)}
    for src, dst in names.items():
        if dst in ints:
            cols[dst] = np.rint(read_column(table, src, np.float64)).astype(np.int64)
        else:
            cols[dst] = read_column(table, src, np.float64)
    order = np.lexsort((cols["t"], cols["pair_id"]))
    return LateralPairs(**{k: v[order] for k, v in cols.items()})


def load_us101(path: str | Path | None = None) -> VehicleTrajectories:
    """Read the US-101 single-vehicle trajectories (already SI).

    Parameters
    ----------
    path : str or Path, optional
        The ``.csv`` or ``.csv.gz`` file; default
        :data:`~avrisk.learning.ngsim.files.US101_FILE` in
        :func:`~avrisk.learning.ngsim.files.ngsim_dir`, which must then name a
        folder holding the original files (``$AVRISK_NGSIM_DIR``): the package
        does not ship US-101.

    Returns
    -------
    VehicleTrajectories
        Sorted by vehicle and frame.
    """
    path = Path(path) if path is not None else ngsim_file([US101_FILE])
    table = pa_csv.read_csv(path)
    names = ["Vehicle_ID", "Frame_ID", "Global_Time", "local_x(m)", "local_y(m)",
             "v_Vel(m)", "v_Acc(m)", "Space_Headway(m)", "Time_Headway"]  # fmt: skip
    _require(table, names, path)
    vid = read_column(table, "Vehicle_ID", np.int64)
    frame = read_column(table, "Frame_ID", np.int64)
    order = np.lexsort((frame, vid))
    space = read_column(table, "Space_Headway(m)", np.float64)
    timeh = read_column(table, "Time_Headway", np.float64)
    return VehicleTrajectories(
        vehicle_id=vid[order],
        frame=frame[order],
        t=read_column(table, "Global_Time", np.float64)[order] * 1e-3,
        lateral=read_column(table, "local_x(m)", np.float64)[order],
        x=read_column(table, "local_y(m)", np.float64)[order],
        speed=read_column(table, "v_Vel(m)", np.float64)[order],
        accel=read_column(table, "v_Acc(m)", np.float64)[order],
        space_headway=np.where(space > 0, space, np.nan)[order],
        time_headway=np.where(timeh < 9999.0, timeh, np.nan)[order],
    )


def periods_of(pairs: CarFollowingPairs) -> tuple[str, ...]:
    """The recording periods of ``pairs``, sorted (e.g. ``"0400pm-0415pm"``)."""
    return tuple(str(p) for p in np.unique(pairs.period))


def lateral_pair_split(
    lateral: LateralPairs, pairs: CarFollowingPairs, test_fraction: float = 0.2
) -> NDArray[np.str_]:
    """Train/test split of the lateral pairs that does not leak through I-80 pairs.

    Both files cover 16:00-16:15 with the same NGSIM vehicle ids (different
    reconstructions). A lateral pair is ``"test"`` if its follower is a test
    follower of the car-following pairs in that period, or if a fixed hash of
    the follower id falls in ``test_fraction`` and the follower is not a train
    follower there; otherwise ``"train"``.

    Parameters
    ----------
    lateral : LateralPairs
    pairs : CarFollowingPairs
    test_fraction : float, default=0.2

    Returns
    -------
    ndarray of str, shape (N,)
        Per row of ``lateral``.
    """
    in_period = pairs.period == LATERAL_PERIOD
    test_ids = set(pairs.follower_id[in_period & (pairs.split == "test")].tolist())
    train_ids = set(pairs.follower_id[in_period & (pairs.split == "train")].tolist())
    out = np.full(len(lateral), "train", dtype="<U5")
    for vid in np.unique(lateral.follower_id):
        rows = lateral.follower_id == vid
        v = int(vid)
        hashed = zlib.crc32(f"i80-0400-{v}".encode()) / 2**32 < test_fraction
        if v in test_ids or (hashed and v not in train_ids):
            out[rows] = "test"
    return out
