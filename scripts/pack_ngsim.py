"""Pack the NGSIM I-80 files that training reads into ``avrisk/data/ngsim/``.

Command (from the repository root)::

    .venv/bin/python scripts/pack_ngsim.py --source /work/shared/data/ngsim

reads the original files (``i80_cf_pairs.csv.gz`` and
``i80_0400_0415_emd_cf_pairs.parquet``; provenance in the source folder's
``SOURCE.md``) and writes, into ``--out`` (default the package's folder):

* one zstd Parquet file per data set (:data:`avrisk.learning.ngsim.files.I80_PAIRS`
  and :data:`~avrisk.learning.ngsim.files.I80_LATERAL`), every row, only the columns
  the loaders read; the I-80 pairs file's ``spacing`` and ``dv`` are left out
  when they equal :func:`~avrisk.learning.ngsim.packed.i80_derived_columns` bit for
  bit (the loader recomputes them). A float column whose values are decimals
  with ``k`` places is stored as the integers ``value * 10**k`` (field
  metadata ``DECIMALS_KEY``), with the values that are not (e.g. ``-0.0`` or
  ``4.4e-16``) in a float64 column beside it, when that is smaller than
  float64;
* ``SOURCE.md``: provenance, what was kept, sha256 of sources and outputs.

The script then loads both forms with the loaders and stops with an error
unless every array is bit-identical.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import io
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from avrisk.learning.ngsim.files import (
    I80_LATERAL,
    I80_PAIRS,
    NgsimFiles,
    default_ngsim_dir,
)
from avrisk.learning.ngsim.loaders import (
    I80_FEET_COLUMNS,
    I80_LATERAL_COLUMNS,
    I80_PAIRS_COLUMNS,
    load_i80_lateral,
    load_i80_pairs,
    read_i80_pairs_table,
)
from avrisk.learning.ngsim.packed import (
    DECIMALS_KEY,
    EXCEPTIONS_SUFFIX,
    i80_derived_columns,
)

#: Most decimals tried for a float column (10**15 * |value| must stay < 2**53).
MAX_DECIMALS = 15
#: zstd level of the packed files.
ZSTD_LEVEL = 19

Columns = dict[pa.Field, pa.Array]


def _bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.int64)


def _table(columns: Columns) -> pa.Table:
    return pa.table(list(columns.values()), schema=pa.schema(list(columns)))


def decimal_columns(name: str, col: pa.Array) -> Columns:
    """Float column ``name`` as integers of the best decimal scale + exceptions.

    The scale ``k`` (0 to :data:`MAX_DECIMALS` places) is the one at which
    most values ``v`` are exactly ``round(v * 10**k) / 10**k`` in float64.
    Returns the integers (field metadata: ``k``), plus a float64 column
    ``name + EXCEPTIONS_SUFFIX`` holding the other values (null elsewhere)
    when there are any. Nulls stay null in both.
    """
    valid = col.is_valid().to_numpy(zero_copy_only=False)
    values = col.to_numpy(zero_copy_only=False)
    best: tuple[int, np.ndarray, np.ndarray] | None = None
    for k in range(MAX_DECIMALS + 1):
        with np.errstate(invalid="ignore"):
            n = np.round(values * 10.0**k)
            fits = valid & np.isfinite(n) & (np.abs(n) < 2.0**53)
        ints = np.where(fits, n, 0).astype(np.int64)
        # Compared as the loader decodes them (an integer loses -0.0's sign).
        exact = fits & (_bits(ints / 10.0**k) == _bits(values))
        if best is None or exact.sum() > best[2].sum():
            best = (k, ints, exact)
        if exact.sum() == valid.sum():
            break
    assert best is not None
    k, ints, exact = best
    field = pa.field(name, pa.int64(), metadata={DECIMALS_KEY: str(k).encode()})
    out: Columns = {field: pa.array(ints, mask=~exact)}
    if (valid & ~exact).any():
        out[pa.field(name + EXCEPTIONS_SUFFIX, pa.float64())] = pa.array(
            values, mask=exact | ~valid
        )
    return out


def _parquet_bytes(table: pa.Table) -> bytes:
    """``table`` as zstd Parquet (dictionaries, delta or byte-split encodings)."""
    strings = [f.name for f in table.schema if pa.types.is_dictionary(f.type)]
    encoding = {
        f.name: "DELTA_BINARY_PACKED"
        if pa.types.is_integer(f.type)
        else "BYTE_STREAM_SPLIT"
        for f in table.schema
        if f.name not in strings
    }
    buffer = io.BytesIO()
    pq.write_table(
        table,
        buffer,
        compression="zstd",
        compression_level=ZSTD_LEVEL,
        use_dictionary=strings,
        column_encoding=encoding,
    )
    return buffer.getvalue()


def encode_column(name: str, col: pa.Array) -> Columns:
    """The packed column(s) of one source column.

    Text of integers becomes int64, other text dictionary-encoded strings,
    floats :func:`decimal_columns` where that is smaller; the rest is kept.
    """
    if pa.types.is_dictionary(col.type) or pa.types.is_string(col.type):
        strings = col.cast(pa.string())
        try:
            return {pa.field(name, pa.int64()): pc.cast(strings, pa.int64())}
        except pa.ArrowInvalid:
            field = pa.field(name, pa.dictionary(pa.int32(), pa.string()))
            return {field: strings.dictionary_encode()}
    if pa.types.is_floating(col.type):
        plain: Columns = {pa.field(name, pa.float64()): col.cast(pa.float64())}
        decimal = decimal_columns(name, col)
        sizes = [len(_parquet_bytes(_table(c))) for c in (plain, decimal)]
        return decimal if sizes[1] < sizes[0] else plain
    return {pa.field(name, col.type): col}


def pack_table(table: pa.Table) -> pa.Table:
    """Every column of ``table`` encoded by :func:`encode_column`."""
    columns: Columns = {}
    for name in table.column_names:
        columns.update(encode_column(name, table.column(name).combine_chunks()))
    return _table(columns)


def i80_pairs_columns(table: pa.Table) -> list[str]:
    """Columns of the I-80 pairs file to keep (``spacing``/``dv`` only if needed)."""
    keep = [*I80_PAIRS_COLUMNS, *I80_FEET_COLUMNS]
    feet = {n: table.column(n).to_numpy(zero_copy_only=False) for n in I80_FEET_COLUMNS}
    for name, derived in i80_derived_columns(feet).items():
        stored = table.column(name).to_numpy(zero_copy_only=False)
        if not np.array_equal(_bits(stored), _bits(derived)):
            keep.append(name)
    return keep


def assert_identical(a: Any, b: Any, what: str) -> None:
    """Every column of two loader results equal, bit for bit."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        same = (
            np.array_equal(_bits(x), _bits(y))
            if x.dtype == np.float64
            else x.dtype == y.dtype and np.array_equal(x, y)
        )
        if not same:
            sys.exit(f"{what}: column {f.name} differs between packed and original")


def sha256(path: Path) -> str:
    """Hex sha256 of a file."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


SOURCE_MD = """\
# NGSIM I-80 samples shipped with avrisk (packed) — provenance

Everything `avrisk train-drivers`
(`avrisk.learning.training.train.train_drivers`) reads. The loaders of
`avrisk.learning.ngsim.loaders` read these files and return the same arrays,
bit for bit, as from the original files below.

Underlying dataset: **NGSIM (Next Generation Simulation) vehicle trajectories**,
US DOT / FHWA, collected 2005 by video at 10 Hz: I-80 in Emeryville, CA
(eastbound, 13 April 2005). The original NGSIM data is a US-government work in
the public domain. These are real NGSIM trajectories that other people already
processed and published; their repositories have no LICENSE file.

* `{pairs_packed}` — from `{pairs_original}`: I-80 leader–follower
  car-following pairs (16:00–16:15 and 17:00–17:15), in feet, ft/s, ft/s².
  Source: github.com/TeRyZh/Segment-based-Calibration-of-Car-Following-Dynamics,
  commit `89f4f0c2fc4bfe1d975c70c7ce681d080a16f19c`, folder `cf_ngsim_I80/`
  (the authors' reconstructed I-80 trajectories, cut into stable
  single-leader episodes); `lane_id` and `split` from its `manifest.csv`.
  The period 17:15–17:30 is held back by the project for independent
  evaluation and is not here.
* `{lateral_packed}` — from `{lateral_original}`:
  I-80 16:00–16:15 car-following pairs with lateral position, SI units. Source:
  github.com/durraniu/R_workshop_materials_NGSIM_data, commit
  `cc1d26429f15d150b7ee909b0d49bed1f17e3bd7`, `data/tidy/df.parquet`
  (the EMD-reconstructed I-80 file of Shuoxuan/NGSIM_Cleaned_Dataset, cut into
  pairs by `code/final/02_data_transformation.R`).

Not shipped: the US-101 sample (`us101_vehicle_subset.csv.gz`, used only by
`benchmarks/driver_realism.py`) and the pairs manifest; see the original
folder's `SOURCE.md`.

## What was kept

Every row, and the columns the loaders read. Dropped: {pairs_dropped} from the
pairs, {lateral_dropped} from the lateral pairs (the loader recomputes a
dropped `spacing` or `dv` from the other columns: the same values, bit for bit).
Float columns that hold decimals of `k` places are stored as the integers
`value * 10**k` (Parquet field metadata `{decimals_key}` = `k`), with the few
values that are not such decimals in a float64 column `<name>{suffix}`;
integer-valued text columns as integers. zstd level {level}.

| file | rows | bytes | sha256 |
|---|---|---|---|
{packed_rows}

## Source files

| file | bytes | sha256 |
|---|---|---|
{source_rows}

## Made by

```
{command}
```
"""


def main(argv: list[str] | None = None) -> None:
    """Command line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--source",
        type=Path,
        required=True,
        help="folder holding the original NGSIM files (and their SOURCE.md)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=default_ngsim_dir(),
        help="folder for the packed files and SOURCE.md (default: the package's)",
    )
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(argv)
    src: Path = args.source
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    pairs = read_i80_pairs_table(src / I80_PAIRS.original)
    lateral = pq.read_table(src / I80_LATERAL.original)
    jobs: list[tuple[NgsimFiles, pa.Table, list[str], Callable[[Path], Any]]] = [
        (I80_PAIRS, pairs, i80_pairs_columns(pairs), load_i80_pairs),
        (I80_LATERAL, lateral, ["pair_id", *I80_LATERAL_COLUMNS], load_i80_lateral),
    ]
    dropped = []
    for files, table, keep, load in jobs:
        (out / files.packed).write_bytes(_parquet_bytes(pack_table(table.select(keep))))
        assert_identical(
            load(out / files.packed), load(src / files.original), files.packed
        )
        dropped.append(", ".join(f"`{c}`" for c in table.column_names if c not in keep))
        print(f"{files.packed}: {(out / files.packed).stat().st_size:,} bytes")

    def row(path: Path, rows: int | None = None) -> str:
        n = "" if rows is None else f"{rows:,} | "
        return f"| `{path.name}` | {n}{path.stat().st_size:,} | `{sha256(path)}` |"

    (out / "SOURCE.md").write_text(
        SOURCE_MD.format(
            pairs_packed=I80_PAIRS.packed,
            pairs_original=I80_PAIRS.original,
            lateral_packed=I80_LATERAL.packed,
            lateral_original=I80_LATERAL.original,
            pairs_dropped=dropped[0],
            lateral_dropped=dropped[1],
            decimals_key=DECIMALS_KEY.decode(),
            suffix=EXCEPTIONS_SUFFIX,
            level=ZSTD_LEVEL,
            packed_rows="\n".join(
                row(out / f.packed, t.num_rows) for f, t, _, _ in jobs
            ),
            source_rows="\n".join(row(src / f.original) for f, _, _, _ in jobs),
            command=shlex.join([".venv/bin/python", "scripts/pack_ngsim.py", *argv]),
        )
    )


if __name__ == "__main__":
    main()
