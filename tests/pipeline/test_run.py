import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.rare import FixedCovNormal, Product, StageBatch
from avrisk.testing import gaussian_linear_problem
from tests.monitors import Counting

PROBLEM = gaussian_linear_problem(2, p=1e-4)
NAMES = ["x0", "x1"]
CE = RunSettings(
    method="ce",
    gamma=0.0,
    gamma_test=(0.5,),
    rho=0.1,
    n_per_iter=2000,
    n_iter=4,
    n_final=20_000,
    seed=3,
)


def with_crash_flag(x):
    return {"f": PROBLEM.f(x), "crash": PROBLEM.f(x) < -1.0}


def without_clock(estimate):
    return {k: v for k, v in estimate.items() if k != "wall_time_s"}


def run(path, settings=CE, f=with_crash_flag):
    return run_estimation(
        RunDirectory(path, NAMES),
        PROBLEM.base,
        f,
        settings,
        context={"scenario": {"name": "gaussian"}},
    )


def test_a_run_leaves_config_samples_checkpoint_and_a_versioned_summary(tmp_path):
    summary = run(tmp_path / "run")
    files = sorted(p.name for p in (tmp_path / "run").iterdir())
    assert files == [
        ".lock",
        "checkpoint.json",
        "config.json",
        "manifest.json",
        "samples.parquet",
        "summary.json",
    ]
    assert summary["schema"] == "avrisk.summary/1"
    est = summary["estimate"]
    assert abs(est["p"] - PROBLEM.p_exact) < 5 * est["stderr"]
    assert [g["gamma"] for g in est["by_gamma"]] == [0.0, 0.5]
    # CE's check after its stages, and the rays a search takes in low dimension
    audit = (
        est["details"]["audit"]["n_calls"] + est["details"]["directional"]["n_calls"]
    )
    assert summary["timing"]["rollouts_evaluated"] == 4 * 2000 + 20_000 + audit
    table = pq.read_table(tmp_path / "run" / "samples.parquet")
    assert table.num_rows == 4 * 2000 + 20_000 + audit
    for col in (
        "phase",
        "stage",
        "iteration",
        "sample_id",
        "seed",
        "x0",
        "x1",
        "log_p0",
        "log_p_proposal",
        "log_weight",
        "weight",
        "f",
        "crash",
    ):
        assert col in table.column_names
    final = table.filter(pc.equal(table["phase"], "final"))
    w = final.column("weight").to_numpy()
    hits = final.column("f").to_numpy() <= 0.0
    assert np.mean(w * hits) == pytest.approx(est["p"], rel=1e-9)
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    assert checkpoint["iterations_done"] == 4 and len(checkpoint["history"]) == 4


def test_rerunning_a_complete_run_reads_it_back_without_evaluating(tmp_path):
    first = run(tmp_path / "run")
    calls = []
    again = run(tmp_path / "run", f=lambda x: calls.append(len(x)) or PROBLEM.f(x))
    assert calls == [] and again == first


def test_a_directory_holding_a_different_run_is_refused_by_name(tmp_path):
    run(tmp_path / "run")
    other = RunSettings(**{**CE.to_dict(), "seed": 4})
    with pytest.raises(
        RunDirectoryError, match=r"different run \(differs in: settings.seed\)"
    ):
        run(tmp_path / "run", settings=other)


def test_a_run_from_before_a_default_changed_resumes_only_with_the_former_value(
    tmp_path,
):
    # splitting_is refreshed nothing at gamma until two rounds became the
    # default; such a run recorded no value, and must not resume as the new
    # default
    small = {"method": "splitting_is", "gamma": 0.0, "n_particles": 300}
    former = RunSettings(**small, n_final=600, refresh_rounds=0)
    first = run(tmp_path / "run", settings=former)
    recorded = json.loads((tmp_path / "run" / "config.json").read_text())
    assert "refresh_rounds" not in recorded["settings"]
    with pytest.raises(
        RunDirectoryError, match=r"differs in: settings.refresh_rounds\)"
    ):
        run(tmp_path / "run", settings=RunSettings(**small, n_final=600))
    assert run(tmp_path / "run", settings=former) == first


def test_a_non_run_directory_with_files_is_refused_and_left_as_found(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(RunDirectoryError, match="not an avrisk run directory"):
        run(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]  # no .lock
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_nan_before_anything_is_recorded_leaves_no_directory(tmp_path):
    with pytest.raises(ValueError, match="NaN"):
        run(tmp_path / "run", f=lambda x: np.full(len(x), np.nan))
    assert not (tmp_path / "run").exists()


def test_an_interrupted_run_resumes_to_the_uninterrupted_result(tmp_path):
    reference = run(tmp_path / "reference")
    calls = []

    def interrupted(x):
        if len(calls) == 3:  # stages 1-3 recorded, then the "machine dies"
            raise KeyboardInterrupt
        calls.append(len(x))
        return with_crash_flag(x)

    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", f=interrupted)
    assert (tmp_path / "run" / "chunks").is_dir()
    resumed = run(tmp_path / "run")
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    assert resumed["timing"]["rollouts_replayed"] == 3 * 2000


def test_bad_settings_are_rejected_by_name():
    with pytest.raises(ValueError, match="estimator 'ce': rho: .* less than 1"):
        RunSettings("ce", rho=2.0)
    # the default is splitting_is, which has no rho
    with pytest.raises(ValueError, match="'splitting_is': rho: Extra inputs"):
        RunSettings(rho=0.1)
    with pytest.raises(ValueError, match="method must be one of .*'naive'"):
        RunSettings(method="no_such_method")
    with pytest.raises(ValueError, match="n_final: .* greater than or equal to 1"):
        RunSettings(n_final=0)
    with pytest.raises(ValueError, match="'naive': rho: Extra inputs"):
        RunSettings("naive", rho=0.1)


SCRIPT = """
import sys, time
from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.testing import gaussian_linear_problem

PROBLEM = gaussian_linear_problem(2, p=1e-4)

def slow(x):
    time.sleep(0.4)
    return {"f": PROBLEM.f(x), "crash": PROBLEM.f(x) < -1.0}

options = __SETTINGS__
settings = RunSettings(**{**options, "gamma_test": tuple(options["gamma_test"])})
run_estimation(RunDirectory(sys.argv[1], ["x0", "x1"]), PROBLEM.base, slow, settings,
               context={"scenario": {"name": "gaussian"}})
""".replace("__SETTINGS__", repr(CE.to_dict()))


@pytest.mark.slow
def test_a_run_killed_with_sigkill_resumes_to_the_uninterrupted_result(tmp_path):
    reference = run(tmp_path / "reference")
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(tmp_path / "run")], cwd=root
    )
    chunks = tmp_path / "run" / "chunks"
    deadline = time.time() + 60
    while time.time() < deadline and len(list(chunks.glob("*.parquet"))) < 2:
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (tmp_path / "run" / "summary.json").exists()
    resumed = run(tmp_path / "run")
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    # The kill can fall between the second chunk's file and its record, so
    # only the first chunk is sure to be recorded (and replayed, not rerun).
    assert resumed["timing"]["rollouts_replayed"] >= 2000


def test_float32_exact_parameters_are_stored_as_float32_and_resume_exactly(tmp_path):
    # One block samples float32-rounded values (as the xi block does): its
    # column is stored in half the space, and the run still resumes exactly.
    base = Product(
        [
            FixedCovNormal(np.zeros(1), cov=np.eye(1), float32_samples=True),
            FixedCovNormal(np.zeros(1), cov=np.eye(1)),
        ]
    )

    def run_on(path, f=with_crash_flag):
        return run_estimation(RunDirectory(path, NAMES), base, f, CE)

    reference = run_on(tmp_path / "reference")
    schema = pq.read_schema(tmp_path / "reference" / "samples.parquet")
    assert str(schema.field("x0").type) == "float"
    assert str(schema.field("x1").type) == "double"
    x0 = pq.read_table(tmp_path / "reference" / "samples.parquet")["x0"].to_numpy()
    assert len(np.unique(x0)) > 0.99 * len(x0)  # real draws, not a constant

    calls = []

    def interrupted(x):
        if len(calls) == 3:
            raise KeyboardInterrupt
        calls.append(len(x))
        return with_crash_flag(x)

    with pytest.raises(KeyboardInterrupt):
        run_on(tmp_path / "run", f=interrupted)
    resumed = run_on(tmp_path / "run")
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    assert resumed["timing"]["rollouts_replayed"] == 3 * 2000


def test_a_column_float32_exact_in_one_chunk_only_is_gathered_as_float64(tmp_path):
    directory = RunDirectory(tmp_path / "run", NAMES)
    directory.claim({"test": 1})
    exact = np.array([[0.5, 1.0], [0.25, 2.0]])
    inexact = np.array([[0.1, 1.0], [0.2, 2.0]])
    for chunk, x in enumerate((exact, inexact)):
        directory.chunks.record(
            StageBatch(
                stage=1,
                chunk=chunk,
                ids=np.arange(2) + 2 * chunk,
                x=x,
                values=np.zeros(2),
                extras={},
                log_p0=np.zeros(2),
                log_q=np.zeros(2),
                seeds=np.arange(2),
            )
        )
    assert str(pq.read_schema(directory.chunks.path(1, 0)).field("x0").type) == "float"
    np.testing.assert_array_equal(directory.chunks.cached(1, 1).x, inexact)
    directory.finish({})
    table = directory.samples()
    assert str(table.schema.field("x0").type) == "double"
    np.testing.assert_array_equal(table["x0"].to_numpy(), [0.5, 0.25, 0.1, 0.2])


def test_any_registered_estimator_runs_and_resumes_through_the_pipeline(tmp_path):
    # subset simulation: no importance weights, MCMC moves through evaluate()
    splitting = RunSettings("splitting", gamma=0.0, seed=2, n_particles=1500)
    reference = run(tmp_path / "reference", settings=splitting)
    assert reference["method"] == "splitting"
    per_replicate = reference["estimate"]["details"]["levels"]  # two replicates
    assert len(per_replicate) == 2
    assert all(len(one) in (4, 5) for one in per_replicate)  # 1e-4 = 0.1^4, +- 1
    calls = []

    def interrupted(x):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(len(x))
        return with_crash_flag(x)

    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", settings=splitting, f=interrupted)
    resumed = run(tmp_path / "run", settings=splitting)
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    assert resumed["timing"]["rollouts_replayed"] == sum(calls)  # P0, 1 round
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    assert len(checkpoint["levels"]) == sum(len(one) for one in per_replicate)


def flaky(failing):
    """``f`` whose evaluation fails (status 1, NaN) where ``failing(x)``."""

    def f(x):
        bad = failing(x)
        return {
            "f": np.where(bad, np.nan, PROBLEM.f(x)),
            "status": bad.astype(np.int8),
        }

    return f


def test_failed_rollouts_bracket_p_and_are_evaluated_again_on_rerun(tmp_path):
    naive = RunSettings("naive", gamma=0.0, gamma_test=(0.5,), n_final=30_000, seed=1)
    clean = run(tmp_path / "clean", settings=naive)["estimate"]["by_gamma"][0]
    # some of the most dangerous-looking rollouts (largest x0) fail: the worst case
    fails = flaky(lambda x: x[:, 0] > 3.7)
    summary = run(tmp_path / "run", settings=naive, f=fails)
    g = summary["estimate"]["by_gamma"][0]
    assert g["n_failed"] > 0
    assert g["p"] <= clean["p"] <= g["p_if_failed_dangerous"]
    assert g["ci"][0] <= clean["p"] <= g["ci"][1]
    table = pq.read_table(tmp_path / "run" / "samples.parquet")
    status, chunk = table["status"].to_numpy(), table["chunk"].to_numpy()
    assert int(status.sum()) == g["n_failed"]
    to_redo = np.isin(chunk, chunk[status != 0]).sum()
    # rerunning evaluates the failed rollouts again; they succeed now
    calls = []
    again = run(
        tmp_path / "run",
        settings=naive,
        f=lambda x: calls.append(len(x)) or flaky(lambda x: x[:, 0] > 99)(x),
    )
    assert 0 < sum(calls) == to_redo < 30_000  # only chunks holding failures
    assert again["estimate"]["by_gamma"][0]["n_failed"] == 0
    assert again["estimate"]["by_gamma"][0]["p"] == clean["p"]


def test_a_rerun_counts_each_rollout_once_replayed_or_simulated_again(tmp_path):
    naive = RunSettings("naive", gamma=0.0, gamma_test=(0.5,), n_final=30_000, seed=1)
    path = tmp_path / "run"
    run(path, settings=naive, f=flaky(lambda x: x[:, 0] > 3.7))
    chunk = pq.read_table(path / "samples.parquet", columns=["chunk", "status"])
    failed_chunks = chunk["chunk"].to_numpy()[chunk["status"].to_numpy() != 0]
    to_redo = int(np.isin(chunk["chunk"].to_numpy(), failed_chunks).sum())
    monitor = Counting()
    again = run_estimation(
        RunDirectory(path, NAMES),
        PROBLEM.base,
        flaky(lambda x: x[:, 0] > 99),
        naive,
        context={"scenario": {"name": "gaussian"}},
        monitor=monitor,
    )
    # a chunk holding failed rollouts is simulated again, not also replayed
    assert 0 < monitor.simulated == to_redo
    assert monitor.replayed + monitor.simulated == monitor.total == 30_000
    assert again["timing"]["rollouts_replayed"] == monitor.replayed


def test_too_many_failures_stop_the_run_with_a_clear_message(tmp_path):
    from avrisk.rare.estimation_context import TooManyFailuresError

    with pytest.raises(TooManyFailuresError, match=r"failed to evaluate .*rerun"):
        run(tmp_path / "run", f=flaky(lambda x: x[:, 1] > 1.5))
    assert (tmp_path / "run" / "chunks").is_dir()  # kept for the rerun


def test_chunks_recorded_by_an_older_version_resume_with_nulls_for_new_columns(
    tmp_path,
):
    naive = RunSettings("naive", gamma=0.0, n_final=20_000, seed=1)
    reference = run(tmp_path / "reference", settings=naive)
    calls = []

    def first_chunk_only(x):
        if calls:
            raise KeyboardInterrupt
        calls.append(len(x))
        return PROBLEM.f(x)  # an older avrisk: no "crash" column

    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", settings=naive, f=first_chunk_only)
    resumed = run(tmp_path / "run", settings=naive)
    assert without_clock(resumed["estimate"]) == without_clock(reference["estimate"])
    crash = pq.read_table(tmp_path / "run" / "samples.parquet")["crash"]
    assert crash.null_count == calls[0] and len(crash) == 20_000


def test_p_is_decomposed_exactly_by_a_label_column(tmp_path):
    def labelled(x):
        return {"f": PROBLEM.f(x), "side": (x[:, 0] > x[:, 1]).astype(np.int8)}

    for settings in (CE, RunSettings("naive", gamma=0.0, n_final=30_000, seed=2)):
        summary = run_estimation(
            RunDirectory(tmp_path / settings.method, NAMES),
            PROBLEM.base,
            labelled,
            settings,
            mechanisms=("side", {0: "left", 1: "right"}),
        )
        main = summary["mechanisms"]["by_gamma"][0]
        parts = main["by_label"]
        assert {p["label"] for p in parts} <= {"left", "right"}
        assert sum(p["p"] for p in parts) == pytest.approx(summary["estimate"]["p"])
        assert sum(p["n_hits"] for p in parts) == summary["estimate"]["n_hits"]
        assert sum(p["share"] for p in parts) == pytest.approx(1.0)
