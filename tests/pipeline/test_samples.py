"""Joining a run's chunk files into samples.parquet."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.samples import conformed, write_samples


def test_a_column_a_chunk_lacks_is_null_there_and_the_rest_is_kept(tmp_path):
    rng = np.random.default_rng(0)
    wide = pa.table({"stage": [0, 0], "a": rng.random(2), "b": rng.random(2)})
    narrow = pa.table({"stage": [1], "a": rng.random(1)})
    files = []
    for k, table in enumerate((wide, narrow)):
        files.append(tmp_path / f"stage{k:04d}-chunk000000.parquet")
        pq.write_table(table, files[-1])

    target = tmp_path / "samples.parquet"
    write_samples(files, target, [], store_full=False, read_full=pq.read_table)

    joined = pq.read_table(target)
    assert joined.column_names == ["stage", "a", "b"]
    assert joined["stage"].to_pylist() == [0, 0, 1]
    assert joined["a"].to_pylist() == [*wide["a"].to_pylist(), narrow["a"][0].as_py()]
    assert joined["b"].to_pylist() == [*wide["b"].to_pylist(), None]


def test_conformed_orders_and_casts_to_the_schema():
    schema = pa.schema([("b", pa.float64()), ("a", pa.int64()), ("c", pa.float32())])
    table = pa.table({"a": pa.array([1, 2], pa.int32()), "b": [0.5, 1.5]})
    out = conformed(table, schema)
    assert out.schema == schema
    assert out.to_pydict() == {"b": [0.5, 1.5], "a": [1, 2], "c": [None, None]}
