"""What a rollout costs on disk: estimated from the parameters, measured on a chunk."""

import numpy as np
import pyarrow as pa
import pytest
from scipy import sparse

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.pipeline.files import parquet_bytes
from avrisk.pipeline.regenerate import MIN_REGENERATED_DIM
from avrisk.pipeline.sizing import (
    FLOAT32_PARAM_ROW_BYTES,
    OTHER_ROW_BYTES,
    PARAM_ROW_BYTES,
    estimated_row_bytes,
    marginal_row_bytes,
)
from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.testing import gaussian_linear_problem


def test_a_small_chunk_measures_what_a_row_adds_to_a_large_table():
    rng = np.random.default_rng(0)
    n = 40_000
    large = pa.table({f"x{i}": rng.normal(size=n) for i in range(10)})
    large = large.append_column("stage", pa.array(np.zeros(n, np.int32)))
    per_row = (len(parquet_bytes(large)) - len(parquet_bytes(large.slice(0, 0)))) / n
    assert 8 * 10 <= per_row <= 10 * 10  # a random double, about PARAM_ROW_BYTES
    assert per_row == pytest.approx(10 * PARAM_ROW_BYTES, rel=0.05)
    # a chunk of 200 rows, whose file is mostly its fixed part, gives the same
    assert marginal_row_bytes(large.slice(0, 200)) == pytest.approx(per_row, rel=0.1)
    assert marginal_row_bytes(large.slice(0, 1)) is None  # no slope to measure


def test_the_estimate_counts_the_parameters_stored():
    big = MIN_REGENERATED_DIM + 8
    blocks = [
        FixedCovNormal(np.zeros(big), precision=sparse.eye_array(big), **kw)
        for kw in ({}, {"float32_samples": True})
    ]
    names = ["a", *(f"big.{i}" for i in range(big))]
    sizes = (PARAM_ROW_BYTES, FLOAT32_PARAM_ROW_BYTES)
    for block, each in zip(blocks, sizes, strict=True):
        base = Product([ScaledBeta(2.0, 2.0), block])
        # the large block is drawn again when read, not stored: one parameter
        assert estimated_row_bytes(names, base) == PARAM_ROW_BYTES + OTHER_ROW_BYTES
        full = estimated_row_bytes(names, base, store_full=True)
        assert full == PARAM_ROW_BYTES + big * each + OTHER_ROW_BYTES
    # without the base, every parameter is stored, as float64
    assert estimated_row_bytes(names) == (1 + big) * PARAM_ROW_BYTES + OTHER_ROW_BYTES


class DiskMonitor:
    """Records what a run tells its monitor, in order."""

    def __init__(self):
        self.calls = []

    def start(self, total, description):
        pass

    def advance(self, n, *, replayed):
        self.calls.append(("advance", n))

    def status(self, text):
        pass

    def disk(self, row_bytes, *, full):
        self.calls.append(("disk", row_bytes, full))


def test_the_disk_measured_on_the_first_chunk_is_what_a_rollout_takes(tmp_path):
    problem = gaussian_linear_problem(2, p=1e-3)
    monitor = DiskMonitor()
    settings = RunSettings("naive", gamma=problem.gamma, n_final=20_000)
    run_dir = RunDirectory(tmp_path / "run", ["x0", "x1"])
    run_estimation(run_dir, problem.base, problem.f, settings, monitor=monitor)
    # once, before the first chunk's advance, on that chunk (8,192 rows)
    assert [c[0] for c in monitor.calls] == ["disk", "advance", "advance", "advance"]
    measured = monitor.calls[0][1]
    written = (run_dir.path / "samples.parquet").stat().st_size / 20_000
    assert measured == pytest.approx(written, rel=0.05)


@pytest.mark.parametrize(
    ("settings", "full"),
    [
        (RunSettings("naive", gamma=0.0, n_final=2000), False),
        (RunSettings("splitting", gamma=0.0, n_particles=500), True),
    ],
    ids=["fresh draws", "subset simulation"],
)
def test_the_first_chunk_says_whether_it_stored_every_column(tmp_path, settings, full):
    # a large block is left out of fresh draws only (drawn again when read)
    big = MIN_REGENERATED_DIM + 8
    block = FixedCovNormal(np.zeros(big), precision=sparse.eye_array(big))
    base = Product([ScaledBeta(2.0, 2.0), block])
    names = ["a", *(f"big.{i}" for i in range(big))]
    monitor = DiskMonitor()
    run_dir = RunDirectory(tmp_path / "run", names, base=base)

    def f(x):
        return 2.0 - x[:, 1:].sum(axis=1) / np.sqrt(big)

    run_estimation(run_dir, base, f, settings, monitor=monitor)
    (first,) = [c for c in monitor.calls if c[0] == "disk"]
    assert first[2] is full
    stored = estimated_row_bytes(names, base, store_full=full)
    assert first[1] == pytest.approx(stored, rel=0.3)
