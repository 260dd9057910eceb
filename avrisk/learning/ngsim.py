"""Loaders for the NGSIM samples the project uses, in SI units.

Three data sets (provenance in the data folder's ``SOURCE.md``), each read
into a frozen dataclass of equal-length numpy columns, one row per 0.1 s sample:

* :func:`load_i80_pairs` -- I-80 leader-follower car-following pairs
  (``i80_cf_pairs.csv.gz``). **The file is in feet**: positions [ft],
  speeds [ft/s] and accelerations [ft/s^2] are converted to m, m/s, m/s^2
  (``FT = 0.3048`` m exactly). Longitudinal only: no lateral position.
* :func:`load_i80_lateral` -- I-80 16:00-16:15 car-following pairs with
  lateral positions (``i80_0400_0415_emd_cf_pairs.parquet``); already SI.
* :func:`load_us101` -- US-101 single-vehicle trajectories with lateral
  positions (``us101_vehicle_subset.csv.gz``); already SI. The vehicles around
  them are not in the file.

The two I-80 data sets, all that training reads, ship with the package in
``avrisk/data/ngsim/`` (the default folder, :func:`ngsim_dir`), packed by
``scripts/pack_ngsim.py`` into Parquet files that the loaders turn into the
same arrays, bit for bit, as the original files (:data:`I80_PAIRS`,
:data:`I80_LATERAL`; the loaders read either form). US-101 does not ship: set
``$AVRISK_NGSIM_DIR`` to a folder holding the original files to use it.

NGSIM frame: ``Local_Y`` runs along the road in the direction of travel and
marks the *front* centre of the vehicle; ``Local_X`` is lateral, from the
left-most edge of the section, increasing to the **right**; lane 1 is the
left-most lane. (avrisk's road frame has ``y`` increasing to the left and lane
0 on the right; :mod:`avrisk.learning.demonstrations` converts.)

One I-80 period (17:15-17:30) is held back by the project for independent
evaluation and is not in these files.
"""

from __future__ import annotations

import dataclasses
import os
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple, Self

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from numpy.typing import NDArray

__all__ = [
    "DECIMALS_KEY",
    "EXCEPTIONS_SUFFIX",
    "FT",
    "I80_FEET_COLUMNS",
    "I80_LANE_WIDTH",
    "I80_LATERAL",
    "I80_LATERAL_COLUMNS",
    "I80_N_LANES",
    "I80_PAIRS",
    "I80_PAIRS_COLUMNS",
    "NGSIM_DIR_ENV",
    "US101_FILE",
    "US101_LANE_WIDTH",
    "CarFollowingPairs",
    "LateralPairs",
    "NgsimFiles",
    "VehicleTrajectories",
    "default_ngsim_dir",
    "episode_bounds",
    "i80_derived_columns",
    "lateral_pair_split",
    "load_i80_lateral",
    "load_i80_pairs",
    "load_us101",
    "ngsim_dir",
    "ngsim_file",
    "read_i80_pairs_table",
]

#: One international foot [m].
FT = 0.3048
#: Main-line lanes of I-80 in the study area (lane 7 is the on-ramp).
I80_N_LANES = 6
#: Nominal lane width of I-80 and US-101 (12 ft) [m].
I80_LANE_WIDTH = US101_LANE_WIDTH = 12 * FT
#: Environment variable naming the folder that holds the NGSIM files.
NGSIM_DIR_ENV = "AVRISK_NGSIM_DIR"


class NgsimFiles(NamedTuple):
    """File names of one data set, in the order the loaders look for them.

    Both hold the same data (the loaders return the same arrays).

    Attributes
    ----------
    original : str
        The file described in the original folder's ``SOURCE.md``.
    packed : str
        The compact Parquet file ``scripts/pack_ngsim.py`` makes from it, as
        shipped in :func:`default_ngsim_dir`.
    """

    original: str
    packed: str


#: I-80 car-following pairs (:func:`load_i80_pairs`).
I80_PAIRS = NgsimFiles("i80_cf_pairs.csv.gz", "i80_cf_pairs.parquet")
#: I-80 16:00-16:15 pairs with lateral positions (:func:`load_i80_lateral`).
I80_LATERAL = NgsimFiles(
    "i80_0400_0415_emd_cf_pairs.parquet", "i80_0400_0415_lateral_pairs.parquet"
)
#: US-101 trajectories (:func:`load_us101`); not shipped with the package.
US101_FILE = "us101_vehicle_subset.csv.gz"

#: Columns of the I-80 pairs file that :func:`load_i80_pairs` reads, besides
#: the ones in feet.
I80_PAIRS_COLUMNS = (
    "pair_id", "period", "follower_id", "leader_id", "lane_id", "split",
    "in_manifest", "t",
)  # fmt: skip
#: Columns of the I-80 pairs file in feet, ft/s or ft/s^2, apart from those of
#: :func:`i80_derived_columns`.
I80_FEET_COLUMNS = (
    "x_follower", "v_follower", "a_follower", "x_leader", "v_leader", "a_leader",
    "leader_length",
)  # fmt: skip
#: Columns of the lateral pairs file and the :class:`LateralPairs` fields they
#: fill (besides ``pair_id``).
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
#: Field metadata key of a packed float column stored as integers: the number
#: ``k`` of decimals (value = integer / 10**k).
DECIMALS_KEY = b"avrisk.decimals"
#: Suffix of the float64 column that holds, where not null, the values of a
#: packed decimal column that are not exact decimals.
EXCEPTIONS_SUFFIX = ".float64"

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]


def default_ngsim_dir() -> Path:
    """The package folder holding the shipped (packed) NGSIM files."""
    return Path(str(resources.files("avrisk") / "data" / "ngsim"))


def ngsim_dir(path: str | Path | None = None) -> Path:
    """The folder holding the NGSIM files.

    Parameters
    ----------
    path : str or Path, optional
        Explicit folder; else ``$AVRISK_NGSIM_DIR``; else the package's folder
        (:func:`default_ngsim_dir`), which holds the I-80 data sets only.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If the folder does not exist.
    """
    chosen = path if path is not None else os.environ.get(NGSIM_DIR_ENV)
    folder = default_ngsim_dir() if chosen is None else Path(chosen)
    if not folder.is_dir():
        raise FileNotFoundError(f"NGSIM folder {folder} does not exist")
    return folder


def ngsim_file(names: Sequence[str], path: str | Path | None = None) -> Path:
    """The first of ``names`` that the NGSIM folder holds.

    Parameters
    ----------
    names : sequence of str
        File names, in order of preference (e.g. :data:`I80_PAIRS`).
    path : str or Path, optional
        The folder, as for :func:`ngsim_dir`.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If the folder does not exist or holds none of ``names``; the message
        names the folder and the files.
    """
    folder = ngsim_dir(path)
    for name in names:
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(
        f"NGSIM folder {folder} lacks {' or '.join(names)}; pass the folder "
        f"holding it or set ${NGSIM_DIR_ENV} (see its SOURCE.md)"
    )


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


def _col(table: pa.Table, name: str, dtype: Any) -> NDArray[Any]:
    col = table.column(name)
    if pa.types.is_dictionary(col.type):
        col = col.cast(pa.string())
    arr = col.to_numpy(zero_copy_only=False)
    if dtype is str:
        return np.asarray(arr, dtype=np.str_)
    if dtype is np.float64:
        return _decode_decimals(table, name, np.asarray(arr, dtype=np.float64))
    return np.asarray(arr, dtype=dtype)


def _decode_decimals(table: pa.Table, name: str, values: FloatArray) -> FloatArray:
    """Undo the packed decimal form of column ``name`` (no-op for other columns).

    The integers ``n`` (< 2**53, exact in float64) become ``n / 10**k``, the
    correctly rounded float64 of the decimal, as a CSV parser gives it.
    """
    metadata = table.schema.field(name).metadata or {}
    if DECIMALS_KEY not in metadata:
        return values
    values = values / 10.0 ** int(metadata[DECIMALS_KEY])
    exceptions = name + EXCEPTIONS_SUFFIX
    if exceptions in table.column_names:
        col = table.column(exceptions)
        exact = col.to_numpy(zero_copy_only=False)
        values = np.where(col.is_valid().to_numpy(zero_copy_only=False), exact, values)
    return values


def _require(table: pa.Table, names: Sequence[str], path: Path) -> None:
    missing = [n for n in names if n not in table.column_names]
    if missing:
        raise ValueError(f"{path} lacks the columns {missing}; see SOURCE.md")


def i80_derived_columns(feet: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """The I-80 pairs file's ``spacing`` [ft] and ``dv`` [ft/s] from its other columns.

    The source computed them so in float64, bit for bit; the packed file omits
    them and :func:`load_i80_pairs` recomputes them.

    Parameters
    ----------
    feet : mapping of str to ndarray of float64
        At least the file's ``x_follower``, ``x_leader``, ``leader_length``
        [ft] and ``v_follower``, ``v_leader`` [ft/s], shape (N,).

    Returns
    -------
    dict of str to ndarray of float64, shape (N,)
        ``"spacing"`` and ``"dv"``.
    """
    return {
        "spacing": feet["x_leader"] - feet["x_follower"] - feet["leader_length"],
        "dv": feet["v_follower"] - feet["v_leader"],
    }


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
        default the :data:`I80_PAIRS` file in :func:`ngsim_dir`.

    Returns
    -------
    CarFollowingPairs
        Sorted by pair and time.
    """
    path = Path(path) if path is not None else ngsim_file(I80_PAIRS)
    table = read_i80_pairs_table(path)
    _require(table, [*I80_PAIRS_COLUMNS, *I80_FEET_COLUMNS], path)
    lane = _col(table, "lane_id", np.float64)
    order = np.lexsort((_col(table, "t", np.float64), _col(table, "pair_id", np.int64)))
    feet = {name: _col(table, name, np.float64)[order] for name in I80_FEET_COLUMNS}
    for name, values in i80_derived_columns(feet).items():
        in_file = name in table.column_names
        feet[name] = _col(table, name, np.float64)[order] if in_file else values
    return CarFollowingPairs(
        pair_id=_col(table, "pair_id", np.int64)[order],
        period=_col(table, "period", str)[order],
        follower_id=_col(table, "follower_id", np.int64)[order],
        leader_id=_col(table, "leader_id", np.int64)[order],
        lane=np.where(np.isnan(lane), -1, np.nan_to_num(lane)).astype(np.int64)[order],
        split=_col(table, "split", str)[order],
        in_manifest=_col(table, "in_manifest", np.int64)[order] != 0,
        t=_col(table, "t", np.float64)[order],
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
        default the :data:`I80_LATERAL` file in :func:`ngsim_dir`.

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
    cols: dict[str, NDArray[Any]] = {"pair_id": _col(table, "pair_id", str)}
    for src, dst in names.items():
        if dst in ints:
            cols[dst] = np.rint(_col(table, src, np.float64)).astype(np.int64)
        else:
            cols[dst] = _col(table, src, np.float64)
    order = np.lexsort((cols["t"], cols["pair_id"]))
    return LateralPairs(**{k: v[order] for k, v in cols.items()})


def load_us101(path: str | Path | None = None) -> VehicleTrajectories:
    """Read the US-101 single-vehicle trajectories (already SI).

    Parameters
    ----------
    path : str or Path, optional
        The ``.csv`` or ``.csv.gz`` file; default :data:`US101_FILE` in
        :func:`ngsim_dir`, which must then name a folder holding the original
        files (``$AVRISK_NGSIM_DIR``): the package does not ship US-101.

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
    vid = _col(table, "Vehicle_ID", np.int64)
    frame = _col(table, "Frame_ID", np.int64)
    order = np.lexsort((frame, vid))
    space = _col(table, "Space_Headway(m)", np.float64)
    timeh = _col(table, "Time_Headway", np.float64)
    return VehicleTrajectories(
        vehicle_id=vid[order],
        frame=frame[order],
        t=_col(table, "Global_Time", np.float64)[order] * 1e-3,
        lateral=_col(table, "local_x(m)", np.float64)[order],
        x=_col(table, "local_y(m)", np.float64)[order],
        speed=_col(table, "v_Vel(m)", np.float64)[order],
        accel=_col(table, "v_Acc(m)", np.float64)[order],
        space_headway=np.where(space > 0, space, np.nan)[order],
        time_headway=np.where(timeh < 9999.0, timeh, np.nan)[order],
    )


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
    in_period = np.char.startswith(pairs.period, "0400")
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
