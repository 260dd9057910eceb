"""The samples table: one format for every table of rollouts avrisk writes.

A run's ``samples.parquet`` and ``avrisk simulate``'s output hold one row per
rollout (:func:`samples_table`). A run records each evaluated chunk as such a
table in ``chunks/`` and, when it finishes, joins them into one
(:func:`write_samples`): columns an older chunk lacks are null there, and the
columns of large blocks a chunk left out (:mod:`avrisk.pipeline.regenerate`)
are listed, with each chunk's digest, in the table's schema metadata.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.layout import chunk_key
from avrisk.pipeline.regenerate import META_KEY, RegenerationError, chunk_meta
from avrisk.rare import StageBatch
from avrisk.rare.problem import FINAL_STAGE

__all__ = [
    "BOOKKEEPING",
    "DENSITIES",
    "full_order",
    "leaving_out",
    "samples_table",
    "table_meta",
    "write_samples",
]

#: Columns of the samples table besides the scenario parameters and extras.
BOOKKEEPING = ("phase", "stage", "iteration", "chunk", "sample_id", "seed")
DENSITIES = ("log_p0", "log_p_proposal", "log_weight", "weight", "f")


def samples_table(
    batch: StageBatch,
    param_names: Sequence[str],
    units: Mapping[str, str] | None = None,
) -> pa.Table:
    """The rows of one evaluated chunk, in the samples-table format.

    One format for every table of rollouts avrisk writes (a run's
    ``samples.parquet``, ``avrisk simulate``'s output)::

        phase, stage, iteration, chunk, sample_id, seed, <parameters of X>,
        log_p0, log_p_proposal, log_weight, weight, f, <other outputs of f>

    Parameters
    ----------
    batch : StageBatch
    param_names : sequence of str
        Names of the columns of ``batch.x``.
    units : mapping of str to str, optional
        Units recorded as the ``unit`` metadata of the named fields.

    Returns
    -------
    pyarrow.Table
        ``len(batch.values)`` rows; a parameter is stored as float32 when that
        loses nothing (e.g. float32-rounded ``xi``).
    """
    n = len(batch.values)
    log_w = batch.log_p0 - batch.log_q
    final = batch.stage == FINAL_STAGE
    columns: dict[str, Any] = {
        "phase": pa.array(["final" if final else "search"] * n),
        "stage": np.full(n, batch.stage, dtype=np.int32),
        "iteration": np.full(n, -1 if final else batch.stage - 1, dtype=np.int32),
        "chunk": np.full(n, batch.chunk, dtype=np.int32),
        "sample_id": batch.ids,
        "seed": batch.seeds,
    }
    columns.update(
        (name, narrowest(col)) for name, col in zip(param_names, batch.x.T, strict=True)
    )
    with np.errstate(over="ignore"):
        weight = np.exp(log_w)
    columns.update(
        log_p0=batch.log_p0,
        log_p_proposal=batch.log_q,
        log_weight=log_w,
        weight=weight,
        f=batch.values,
    )
    columns.update(batch.extras)
    table = pa.table(columns)
    if not units:
        return table
    fields = [
        f.with_metadata({b"unit": units[f.name].encode()}) if f.name in units else f
        for f in table.schema
    ]
    return table.cast(pa.schema(fields))


def narrowest(column: np.ndarray) -> np.ndarray:
    """``column`` as float32 if that loses nothing (e.g. float32-rounded xi)."""
    narrow = column.astype(np.float32)
    return narrow if np.array_equal(narrow, column) else column


def widest_schema(
    schemas: Sequence[pa.Schema], param_names: Sequence[str]
) -> pa.Schema | None:
    """Every chunk's columns, float64 where any stored it, parameters in order.

    Chunks recorded by an earlier avrisk may lack columns that later chunks
    have (a run resumed across versions), chunks with left-out blocks lack
    those: such columns are null in their rows.
    """
    if not schemas:
        return None
    wide = {f.name for s in schemas for f in s if f.type == pa.float64()}
    fields: dict[str, pa.Field] = {}
    for schema in schemas:
        for f in schema:
            fields.setdefault(
                f.name, f.with_type(pa.float64()) if f.name in wide else f
            )
    order = full_order(list(fields), param_names)
    return pa.schema([fields[name] for name in order if name in fields])


def full_order(names: Sequence[str], param_names: Sequence[str]) -> list[str]:
    """``names`` in the samples-table order: bookkeeping, parameters, the rest."""
    present = set(names)
    params = [p for p in param_names if p in present]
    rest = [n for n in names if n not in BOOKKEEPING and n not in set(params)]
    return [n for n in names if n in BOOKKEEPING] + params + rest


def leaving_out(table: pa.Table, meta: dict[str, Any]) -> pa.Table:
    """A chunk's rows without the columns ``meta`` lists, ``meta`` in the schema."""
    stored = set(table.column_names)
    present = [c for c in meta["columns"] if c in stored]
    return table.drop_columns(present).replace_schema_metadata(
        {META_KEY: json.dumps(meta)}
    )


def table_meta_json(left_out: Mapping[tuple[int, int], dict[str, Any]]) -> str:
    """samples.parquet's record: the left-out columns once, then each chunk's digest."""
    columns = next(iter(left_out.values()))["columns"]
    if any(m["columns"] != columns for m in left_out.values()):
        raise RegenerationError("the chunks of one run left out different columns")
    return json.dumps(
        {
            "columns": columns,
            "chunks": [
                [s, c, m["rows"], m["sha256"]] for (s, c), m in left_out.items()
            ],
        }
    )


def table_meta(
    schema: pa.Schema,
) -> tuple[list[str], dict[tuple[int, int], dict[str, Any]]]:
    """Left-out columns of a samples table and ``(stage, chunk) -> chunk record``."""
    meta = chunk_meta(schema)
    if meta is None:
        return [], {}
    columns, chunks = meta.get("columns"), meta.get("chunks")
    ok = (
        isinstance(columns, list)
        and all(isinstance(c, str) for c in columns)
        and isinstance(chunks, list)
        and all(
            isinstance(c, list)
            and len(c) == 4
            and all(isinstance(v, int) for v in c[:3])
            and isinstance(c[3], str)
            for c in chunks
        )
    )
    if not ok:
        raise RegenerationError("malformed record of the samples' left-out columns")
    return columns, {
        (s, c): {"columns": columns, "rows": rows, "sha256": digest}
        for s, c, rows, digest in chunks
    }


def conformed(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` cast to ``schema``, missing columns filled with nulls."""
    present = set(table.column_names)
    columns = [
        table[f.name] if f.name in present else pa.nulls(len(table), f.type)
        for f in schema
    ]
    return pa.Table.from_arrays(columns, schema=schema.remove_metadata()).cast(schema)


def write_samples(
    files: Sequence[Path],
    target: Path,
    param_names: Sequence[str],
    *,
    store_full: bool,
    read_full: Callable[[Path], pa.Table],
) -> None:
    """Join the chunk files ``files`` into the samples table ``target``, atomically.

    The table's schema metadata (:data:`~avrisk.pipeline.regenerate.META_KEY`)
    lists the chunks whose large blocks were left out, with their digests;
    with ``store_full`` those columns are drawn again (``read_full(path)``:
    the chunk with every column) and stored instead. A failure (a full disk)
    leaves neither ``target`` nor a temporary file.
    """
    metas = {chunk_key(p): chunk_meta(pq.read_schema(p)) for p in files}
    left_out = {k: m for k, m in metas.items() if m is not None}
    tmp = target.with_name(f".{target.name}.tmp-{os.getpid()}")
    schema = widest_schema(
        [gathered_schema(p, metas[chunk_key(p)], store_full) for p in files],
        param_names,
    )
    if schema is not None and left_out and not store_full:
        schema = schema.with_metadata({META_KEY: table_meta_json(left_out)})
    writer = None
    try:
        for path in files:
            table = read_full(path) if store_full else pq.read_table(path)
            if writer is None:
                writer = pq.ParquetWriter(tmp, schema)
            writer.write_table(conformed(table, schema))
        if writer is not None:
            writer.close()
            os.replace(tmp, target)
    except BaseException:
        if writer is not None:
            with contextlib.suppress(Exception):
                writer.close()
        tmp.unlink(missing_ok=True)  # a full disk leaves no stray temporary
        raise


def gathered_schema(
    path: Path, meta: dict[str, Any] | None, store_full: bool
) -> pa.Schema:
    """A chunk's schema in samples.parquet (left-out columns back if store_full)."""
    schema = pq.read_schema(path).remove_metadata()
    if meta is None or not store_full:
        return schema
    for name in meta["columns"]:
        schema = schema.append(pa.field(name, pa.float64()))
    return schema
