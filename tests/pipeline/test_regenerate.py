"""Large blocks of X left out of a run directory and drawn again, checked."""

import copy
import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import sparse

from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.pipeline.regenerate import (
    META_KEY,
    MIN_REGENERATED_DIM,
    PROPOSALS_FILE,
    RegenerationError,
    large_block_columns,
)
from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.rare.proposals import proposal_from_record, proposal_record

BIG = MIN_REGENERATED_DIM + 8
#: Two small blocks (stored) and a float32-rounded normal block like ``xi``.
BASE = Product(
    [
        ScaledBeta(2.0, 2.0, lo=-1.0, scale=2.0, bounds=(1.0, 20.0)),
        ScaledBeta(2.0, 3.0, lo=0.0, scale=1.0, bounds=(1.0, 20.0)),
        FixedCovNormal(
            np.zeros(BIG),
            precision=sparse.eye_array(BIG, format="csr"),
            max_shift=3.0,
            float32_samples=True,
        ),
    ]
)
NAMES = ["a", "b", *(f"big.{i}" for i in range(BIG))]


def f(x):
    """Low where the big block's mean is high: p about 1e-3."""
    value = 3.0 - x[:, 2:].sum(axis=1) / np.sqrt(BIG) + 0.1 * x[:, 0]
    return {"f": value, "crash": (value < 0).astype(np.int8)}


SETTINGS = {
    "naive": RunSettings("naive", gamma=0.0, n_final=20_000, seed=4),
    "ce": RunSettings(
        "ce", gamma=0.0, rho=0.1, n_per_iter=2000, n_iter=3, n_final=20_000, seed=4
    ),
    "defensive": RunSettings(
        "ce",
        gamma=0.0,
        rho=0.1,
        n_per_iter=2000,
        n_iter=2,
        n_final=10_000,
        defensive=0.2,
        seed=5,
    ),
    "mixture": RunSettings(
        "mixture", gamma=0.0, n_per_iter=2000, n_iter=2, n_final=10_000, seed=6
    ),
    "splitting": RunSettings("splitting", gamma=0.0, seed=2, n_particles=1500),
    "splitting_is": RunSettings(
        "splitting_is", gamma=0.0, seed=2, n_particles=1500, n_final=5000
    ),
}


def run(path, settings, *, base=BASE, store_full=False, fn=f):
    # the run directory's P0 is built apart from the estimator's, as the CLI
    # builds both from the scenario: equal, not the same object
    directory = RunDirectory(
        path, NAMES, base=copy.deepcopy(base), store_full=store_full
    )
    summary = run_estimation(directory, BASE, fn, settings)
    return directory, summary


def without_clock(estimate):
    return {k: v for k, v in estimate.items() if k != "wall_time_s"}


def test_the_blocks_left_out_are_those_of_the_large_blocks_only():
    assert large_block_columns(BASE, NAMES) == NAMES[2:]
    with pytest.raises(ValueError, match="42 coordinates, the run 2"):
        large_block_columns(BASE, ["a", "b"])


@pytest.mark.parametrize("method", sorted(SETTINGS))
def test_left_out_blocks_come_back_bit_for_bit(tmp_path, method):
    settings = SETTINGS[method]
    compact, summary = run(tmp_path / "compact", settings)
    full, reference = run(tmp_path / "full", settings, store_full=True)
    assert without_clock(summary["estimate"]) == without_clock(reference["estimate"])
    stored = pq.read_schema(compact.path / "samples.parquet")
    # subset simulation's points are MCMC moves, not fresh draws: stored in full
    assert (META_KEY in (stored.metadata or {})) == (method != "splitting")
    got, want = compact.samples(), full.samples()
    assert got.column_names == want.column_names
    assert got.num_rows == want.num_rows
    for name in ("f", "log_weight", "a", *NAMES[2:]):
        np.testing.assert_array_equal(
            got[name].to_numpy().astype(np.float64),
            want[name].to_numpy().astype(np.float64),
            err_msg=name,
        )
    rows = [5, 0, got.num_rows - 1]
    assert compact.samples(rows=rows).to_pylist() == got.take(rows).to_pylist()


def test_the_compact_table_is_smaller_and_needs_no_big_columns(tmp_path):
    compact, _ = run(tmp_path / "compact", SETTINGS["naive"])
    full, _ = run(tmp_path / "full", SETTINGS["naive"], base=None)
    assert "big.0" not in pq.read_schema(compact.path / "samples.parquet").names
    assert "big.0" in pq.read_schema(full.path / "samples.parquet").names
    size = {d: (d.path / "samples.parquet").stat().st_size for d in (compact, full)}
    assert size[compact] < 0.25 * size[full]
    proposals = json.loads((compact.path / PROPOSALS_FILE).read_text())
    assert proposals["seed"] == 4 and list(proposals["stages"]) == ["0"]
    # a directory with full columns (as older runs) reads the same with a base
    with_base = RunDirectory(full.path, NAMES, base=BASE)
    assert with_base.samples().equals(full.samples())


def test_a_run_interrupted_mid_stage_resumes_to_the_same_result(tmp_path):
    settings = SETTINGS["ce"]
    _, reference = run(tmp_path / "reference", settings)
    calls = []

    def interrupted(x):
        if len(calls) == 4:  # the search and the final stage's first chunk
            raise KeyboardInterrupt
        calls.append(len(x))
        return f(x)

    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", settings, fn=interrupted)
    chunks = sorted((tmp_path / "run" / "chunks").glob("*.parquet"))
    assert len(chunks) == 4
    assert "big.0" not in pq.read_schema(chunks[0]).names
    directory, resumed = run(tmp_path / "run", settings)
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    assert resumed["timing"]["rollouts_replayed"] == sum(calls)


def test_a_changed_proposal_is_an_error_naming_the_chunk(tmp_path):
    directory, _ = run(tmp_path / "run", SETTINGS["ce"])
    path = directory.path / PROPOSALS_FILE
    record = json.loads(path.read_text())
    record["stages"]["0"]["params"][-1] += 1e-9
    path.write_text(json.dumps(record))
    reread = RunDirectory(directory.path, NAMES, base=BASE)
    rows = json.loads((directory.path / "summary.json").read_text())
    # stored columns only
    assert reread.samples(["f", "a"]).num_rows == rows["estimate"]["n_evals"]
    with pytest.raises(RegenerationError, match=r"stage 0 chunk 0 .*differ"):
        reread.samples()


def test_a_malformed_proposal_record_is_a_clear_error(tmp_path):
    directory, _ = run(tmp_path / "run", SETTINGS["naive"])
    path = directory.path / PROPOSALS_FILE
    record = json.loads(path.read_text())
    record["stages"]["0"] = {"kind": "family", "params": ["0.5"]}
    path.write_text(json.dumps(record))
    reread = RunDirectory(directory.path, NAMES, base=BASE)
    with pytest.raises(RegenerationError, match="stage 0: proposal record: params"):
        reread.samples()
    path.write_text("{not json")
    with pytest.raises(RegenerationError, match="unreadable"):
        RunDirectory(directory.path, NAMES, base=BASE).samples()


def test_reading_left_out_columns_needs_the_base(tmp_path):
    directory, _ = run(tmp_path / "run", SETTINGS["naive"])
    without = RunDirectory(directory.path, NAMES)
    assert without.samples(["f"]).num_rows == 20_000
    with pytest.raises(RunDirectoryError, match="open it with its base"):
        without.samples()


def test_failed_rollouts_are_evaluated_again_in_a_compact_run(tmp_path):
    naive = SETTINGS["naive"]
    _, clean = run(tmp_path / "clean", naive)

    def failing(x):
        out = f(x)
        bad = x[:, 2] > 3.0
        return {"f": np.where(bad, np.nan, out["f"]), "status": bad.astype(np.int8)}

    _, first = run(tmp_path / "run", naive, fn=failing)
    assert first["estimate"]["by_gamma"][0]["n_failed"] > 0
    directory, again = run(
        tmp_path / "run", naive, fn=lambda x: {**f(x), "status": np.zeros(len(x))}
    )
    assert again["estimate"]["p"] == clean["estimate"]["p"]
    assert "big.0" not in pq.read_schema(directory.path / "samples.parquet").names
    np.testing.assert_array_equal(
        directory.samples(["big.3"])["big.3"].to_numpy(),
        RunDirectory(tmp_path / "clean", NAMES, base=BASE)
        .samples(["big.3"])["big.3"]
        .to_numpy(),
    )


@pytest.mark.parametrize("method", ["ce", "defensive", "mixture"])
def test_a_proposal_record_draws_the_same_samples(tmp_path, method):
    run(tmp_path / "run", SETTINGS[method])
    record = json.loads((tmp_path / "run" / PROPOSALS_FILE).read_text())
    final = record["stages"]["0"]
    assert final["kind"] == {"ce": "family"}.get(method, method)
    sampler = proposal_from_record(final, BASE)
    assert proposal_record(sampler, BASE) == final
