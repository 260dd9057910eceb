"""Disk a run's samples take per rollout: estimated before a run, measured on a chunk.

A run's plan states the disk its samples table will take
(:func:`estimated_row_bytes`, from the parameters stored); the first chunk
written measures it (:func:`marginal_row_bytes`), compression and further
outputs of ``f`` included.
"""

from __future__ import annotations

from collections.abc import Sequence

import pyarrow as pa

from avrisk.pipeline.files import parquet_bytes
from avrisk.pipeline.regenerate import large_block_columns
from avrisk.rare import ExponentialFamily, Product

__all__ = [
    "FLOAT32_PARAM_ROW_BYTES",
    "OTHER_ROW_BYTES",
    "PARAM_ROW_BYTES",
    "estimated_row_bytes",
    "marginal_row_bytes",
]

#: Disk a stored parameter takes per rollout in a samples table [B]: a float64
#: draw does not compress, and Parquet's dictionary encoding adds an index to
#: its 8 bytes; a float32-rounded one (a learned driver's ``xi``) takes 4 and
#: its index (fitted to ``highway_default``'s stored ``xi``).
PARAM_ROW_BYTES, FLOAT32_PARAM_ROW_BYTES = 9.5, 5.0
#: Disk the other columns take per rollout (bookkeeping, densities, ``f`` and
#: a simulator's outcomes) [B], fitted to :func:`marginal_row_bytes` of a naive
#: run's samples table on ``highway_idm``.
OTHER_ROW_BYTES = 45


def estimated_row_bytes(
    param_names: Sequence[str],
    base: ExponentialFamily | None = None,
    *,
    store_full: bool = False,
) -> float:
    """Disk a rollout will take in a run's samples, before any is written [B].

    :data:`PARAM_ROW_BYTES` for each parameter stored
    (:data:`FLOAT32_PARAM_ROW_BYTES` for the blocks of ``base`` that draw
    float32-rounded samples), plus :data:`OTHER_ROW_BYTES`. A run directory
    with ``base`` leaves its large blocks out unless ``store_full`` (see
    :class:`~avrisk.pipeline.store.RunDirectory`). Compression and further
    outputs of ``f`` make the real figure differ: :func:`marginal_row_bytes`
    measures it on a chunk.
    """
    if base is None:
        return PARAM_ROW_BYTES * len(param_names) + OTHER_ROW_BYTES
    left_out = set() if store_full else set(large_block_columns(base, param_names))
    total, start = float(OTHER_ROW_BYTES), 0
    for block in base.blocks if isinstance(base, Product) else (base,):
        names = param_names[start : start + block.dim]
        start += block.dim
        each = (
            FLOAT32_PARAM_ROW_BYTES
            if getattr(block, "float32_samples", False)
            else PARAM_ROW_BYTES
        )
        total += each * sum(name not in left_out for name in names)
    return total


def marginal_row_bytes(table: pa.Table) -> float | None:
    """Disk one more row of ``table`` takes in a Parquet file [B]; None under 2 rows.

    The slope between the file of its first half and the file of the whole:
    the file's fixed part (schema, metadata, footer) cancels, so a chunk of a
    few rows gives what a rollout adds to a large samples table.
    """
    half = table.num_rows // 2
    if half == 0:
        return None
    whole = len(parquet_bytes(table))
    first = len(parquet_bytes(table.slice(0, half)))
    return (whole - first) / (table.num_rows - half)
