"""Time joining a run's chunk files into ``samples.parquet``.

A run records each batch it evaluates as a chunk file and joins them into
``samples.parquet`` when it finishes
(:func:`avrisk.pipeline.samples.write_samples`). Subset simulation's chains
evaluate small batches, so a run holds many chunks, each as wide as the
scenario's parameters (``highway_default``: 404 columns of ``xi``, 456 in all
for a paired run). This writes ``--chunks`` synthetic chunk files of
``--rows`` rows and ``--columns`` float columns (every other chunk without
the last tenth of them, as final-stage chunks leave ``xi`` out), joins them
``--repeats`` times and prints the fastest join in seconds. Run it in two
checkouts, each first on ``PYTHONPATH``, to compare them::

    PYTHONPATH=. .venv/bin/python benchmarks/samples_join.py [--chunks 127] \\
        [--rows 28] [--columns 456] [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.samples import write_samples


def write_chunks(folder: Path, chunks: int, rows: int, columns: int) -> list[Path]:
    """``chunks`` Parquet files of ``rows`` rows; odd ones lack the last tenth."""
    rng = np.random.default_rng(0)
    names = [f"c.{j}" for j in range(columns)]
    paths = []
    for k in range(chunks):
        kept = names if k % 2 == 0 else names[: columns - columns // 10]
        table = pa.table(
            {
                "stage": np.full(rows, k, dtype=np.int64),
                "chunk": np.zeros(rows, dtype=np.int64),
                **{name: rng.standard_normal(rows) for name in kept},
            }
        )
        path = folder / f"stage{k:04d}-chunk000000.parquet"
        pq.write_table(table, path)
        paths.append(path)
    return paths


def main() -> None:
    """Write the chunks, join them, print the fastest join [s]."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chunks", type=int, default=127)
    parser.add_argument("--rows", type=int, default=28)
    parser.add_argument("--columns", type=int, default=456)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        files = write_chunks(folder, args.chunks, args.rows, args.columns)
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            write_samples(
                files,
                folder / "samples.parquet",
                [],
                store_full=False,
                read_full=pq.read_table,
            )
            times.append(time.perf_counter() - start)
    print(
        f"{args.chunks} chunks x {args.rows} rows x {args.columns} columns: "
        f"joined in {min(times):.2f} s (fastest of {args.repeats})"
    )


if __name__ == "__main__":
    main()
