"""Damaged or swapped records of a run directory are named, never trusted."""

import json
import shutil

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from avrisk.pipeline import (
    RecordIntegrityWarning,
    RunDirectory,
    RunDirectoryError,
    RunSettings,
    run_estimation,
)
from avrisk.testing import gaussian_linear_problem

PROBLEM = gaussian_linear_problem(2, p=1e-4)
NAMES = ["x0", "x1"]
CE = RunSettings(
    method="ce",
    gamma=0.0,
    rho=0.1,
    n_per_iter=2000,
    n_iter=2,
    n_final=20_000,
    seed=3,
)


def run(path, f=PROBLEM.f):
    return run_estimation(
        RunDirectory(path, NAMES),
        PROBLEM.base,
        f,
        CE,
        context={"scenario": {"name": "gaussian"}},
    )


def expected_rows(summary):
    """The run's samples: CE's stages, then its audit's and its rays' (after them)."""
    details = summary["estimate"]["details"]
    rays = details["directional"]["n_calls"]  # X in two dimensions
    return 2 * 2000 + 20_000 + details["audit"]["n_calls"] + rays


def estimate(summary):
    return {k: v for k, v in summary["estimate"].items() if k != "wall_time_s"}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "run"
    return path, run(path)


@pytest.fixture
def reopened(reference, tmp_path):
    """A copy of the reference run, turned back into recorded chunks."""
    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    RunDirectory(path, NAMES).reopen()
    return path


def chunk(path, stage, index):
    return path / "chunks" / f"stage{stage:04d}-chunk{index:06d}.parquet"


def resumes_to_reference(path, reference, match):
    with pytest.warns(RecordIntegrityWarning, match=match):
        resumed = run(path)
    assert estimate(resumed) == estimate(reference[1])
    return resumed


def test_a_new_run_records_every_chunk_and_the_final_records(reference):
    manifest = json.loads((reference[0] / "manifest.json").read_text())
    assert manifest["schema"] == "avrisk.manifest/1"
    # the search's stages 1-2, the final stage 0, then the audit's from stage 3
    stages = {e["stage"] for e in manifest["chunks"].values()}
    assert {0, 1, 2, 3} <= stages and min(stages - {0, 1, 2}) == 3
    rows = sum(e["rows"] for e in manifest["chunks"].values())
    assert rows == manifest["samples"]["rows"] == expected_rows(reference[1])
    assert len(manifest["summary"]["sha256"]) == 64


def test_a_chunk_from_another_stage_swapped_in_is_named_and_evaluated_again(
    reopened, reference
):
    shutil.copy(chunk(reopened, 1, 0), chunk(reopened, 2, 0))  # same rows, valid
    resumed = resumes_to_reference(
        reopened, reference, r"stage0002-chunk000000.parquet: SHA-256 .* differs"
    )
    assert resumed["timing"]["rollouts_evaluated"] == 2000


def test_a_swapped_chunk_is_caught_by_its_columns_without_a_manifest(
    reopened, reference
):
    (reopened / "manifest.json").unlink()  # a directory from an older avrisk
    shutil.copy(chunk(reopened, 1, 0), chunk(reopened, 2, 0))
    resumes_to_reference(
        reopened, reference, r"stage0002-chunk000000.parquet: holds rows of stage \[1\]"
    )


def test_a_chunk_with_one_altered_f_is_named_and_evaluated_again(reopened, reference):
    path = chunk(reopened, 0, 1)
    table = pq.read_table(path)
    f = table["f"].to_numpy().copy()
    f[17] = -5.0  # now a hit
    table = table.set_column(table.schema.get_field_index("f"), "f", pa.array(f))
    pq.write_table(table, path)
    resumed = resumes_to_reference(
        reopened, reference, r"stage0000-chunk000001.parquet: SHA-256 .* differs"
    )
    assert resumed["timing"]["rollouts_evaluated"] == 8192


def test_a_truncated_chunk_is_named_and_evaluated_again(reopened, reference):
    path = chunk(reopened, 0, 0)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    resumes_to_reference(reopened, reference, r"stage0000-chunk000000.parquet: SHA")


def test_a_chunk_written_but_not_listed_is_evaluated_again(reopened, reference):
    """What ``kill -9`` between writing a chunk and its manifest entry leaves."""
    manifest = json.loads((reopened / "manifest.json").read_text())
    del manifest["chunks"]["stage0000-chunk000002.parquet"]
    (reopened / "manifest.json").write_text(json.dumps(manifest))
    resumes_to_reference(reopened, reference, r"chunk000002.parquet: not listed")


def test_a_chunk_deleted_mid_run_stops_the_finish_and_a_rerun_restores_it(
    tmp_path, reference
):
    path = tmp_path / "run"
    calls = []

    def deleting(x):
        calls.append(len(x))
        if len(calls) == 4:  # stages 1, 2 and the first final chunk are recorded
            chunk(path, 0, 0).unlink()
        return PROBLEM.f(x)

    with pytest.raises(
        RunDirectoryError, match=r"stage0000-chunk000000.parquet: listed .* missing"
    ):
        run(path, f=deleting)
    assert not (path / "summary.json").exists()  # no count of rows it lacks
    resumed = resumes_to_reference(path, reference, r"chunk000000.parquet: listed")
    assert resumed["timing"]["rollouts_evaluated"] == 8192
    table = RunDirectory(path, NAMES).samples(["f"])
    assert table.num_rows == estimate(resumed)["n_evals"]


def test_a_tampered_summary_is_refused_and_a_rerun_recomputes_it(tmp_path, reference):
    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    summary = json.loads((path / "summary.json").read_text())
    summary["estimate"]["p"] *= 10  # well-formed, wrong
    (path / "summary.json").write_text(json.dumps(summary, indent=2))
    with pytest.raises(
        RunDirectoryError, match=r"summary.json: SHA-256 .* rerun the command"
    ):
        RunDirectory(path, NAMES).summary()
    resumed = resumes_to_reference(path, reference, r"summary.json: SHA-256")
    assert resumed["timing"]["rollouts_evaluated"] == 0  # replayed from samples
    assert estimate(RunDirectory(path, NAMES).summary()) == estimate(reference[1])


def test_a_tampered_samples_table_is_refused_and_a_rerun_recomputes_it(
    tmp_path, reference
):
    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    table = pq.read_table(path / "samples.parquet")
    f = pc.if_else(pc.equal(table["sample_id"], 5), -5.0, table["f"])
    table = table.set_column(table.schema.get_field_index("f"), "f", f)
    pq.write_table(table, path / "samples.parquet")
    with pytest.raises(RunDirectoryError, match=r"samples.parquet: SHA-256"):
        RunDirectory(path, NAMES).samples(["f"])
    resumed = resumes_to_reference(path, reference, r"samples.parquet: SHA-256")
    assert resumed["timing"]["rollouts_evaluated"] == expected_rows(reference[1])


def test_a_summary_copied_from_another_run_is_refused(tmp_path, reference):
    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    other = RunSettings(**{**CE.to_dict(), "seed": 4})
    run_estimation(
        RunDirectory(tmp_path / "other", NAMES),
        PROBLEM.base,
        PROBLEM.f,
        other,
        context={"scenario": {"name": "gaussian"}},
    )
    shutil.copy(tmp_path / "other" / "summary.json", path / "summary.json")
    with pytest.raises(RunDirectoryError, match="summary.json: SHA-256"):
        RunDirectory(path, NAMES).summary()


def test_a_directory_without_a_manifest_reads_unverified(tmp_path, reference):
    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    (path / "manifest.json").unlink()
    run_dir = RunDirectory(path, NAMES)
    with pytest.warns(RecordIntegrityWarning, match="read unverified"):
        assert run_dir.summary() == reference[1]
    assert run_dir.samples(["f"]).num_rows == expected_rows(reference[1])
