"""A resume replays recorded rollouts and refuses an ``f`` that changed since.

``f`` here is a Gaussian problem's, changed only near its hits (as an ego that
brakes later changes only the rollouts that come close): typical draws of the
first chunk do not see that change, the recorded rows of lowest ``f`` do.
"""

import numpy as np
import pyarrow.parquet as pq
import pytest

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.pipeline.manifest import RecordIntegrityWarning
from avrisk.pipeline.repeatability import (
    FIRST_ROWS,
    LOWEST_ROWS,
    NotRepeatableError,
    ReplayCheck,
    UncheckedResumeWarning,
    replayed_rows,
)
from avrisk.rare.estimation_context import TooManyFailuresError
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.testing import gaussian_linear_problem
from tests.monitors import Counting

PROBLEM = gaussian_linear_problem(2, p=1e-4)
NAMES = ["x0", "x1"]
CE = RunSettings(
    method="ce", gamma=0.0, rho=0.1, n_per_iter=500, n_iter=3, n_final=2000, seed=3
)
#: Two chunks in one stage.
NAIVE = RunSettings("naive", gamma=0.0, n_final=SAMPLE_CHUNK + 500, seed=1)
NEAR = 0.5


def f(x):
    return {"f": PROBLEM.f(x), "crash": PROBLEM.f(x) < -1.0}


def changed_near_hits(x):
    """``f`` moved by 0.05 where it is below NEAR, the same elsewhere."""
    out = f(x)
    out["f"] = np.where(out["f"] < NEAR, out["f"] + 0.05, out["f"])
    return out


def failing(x):
    return {"f": np.full(len(x), np.nan), "status": np.ones(len(x), dtype=np.int8)}


def run(path, settings=CE, objective=f, check=None, monitor=None):
    return run_estimation(
        RunDirectory(path, NAMES),
        PROBLEM.base,
        objective,
        settings,
        context={"scenario": {"name": "gaussian"}},
        monitor=monitor,
        replay_check=None if check is None else ReplayCheck(check),
    )


def interrupted(path, stages=2):
    """A CE run stopped after its first ``stages`` stages are recorded."""
    calls = []

    def dies(x):
        if len(calls) == stages:
            raise KeyboardInterrupt
        calls.append(len(x))
        return f(x)

    with pytest.raises(KeyboardInterrupt):
        run(path, objective=dies)


def test_a_resume_refuses_an_f_changed_only_near_its_hits(tmp_path):
    path = tmp_path / "run"
    interrupted(path)
    rows = replayed_rows(RunDirectory(path, NAMES))
    assert len(rows) == FIRST_ROWS + LOWEST_ROWS
    values = np.array([batch.values[row] for batch, row in rows])
    assert (values[:FIRST_ROWS] >= NEAR).all()  # typical draws: not changed
    assert (values[FIRST_ROWS:] < NEAR).all()  # the lowest recorded: changed
    with pytest.raises(NotRepeatableError, match="f differs from the run recorded"):
        run(path, objective=changed_near_hits, check=changed_near_hits)


def test_the_same_f_resumes_to_the_same_estimate_and_counts_add_up(tmp_path):
    reference = run(tmp_path / "reference")
    interrupted(tmp_path / "run")
    monitor = Counting()
    resumed = run(tmp_path / "run", check=f, monitor=monitor)
    estimate = {k: v for k, v in resumed["estimate"].items() if k != "wall_time_s"}
    assert estimate == {
        k: v for k, v in reference["estimate"].items() if k != "wall_time_s"
    }
    # the replayed check's rollouts are not counted
    assert monitor.replayed == 2 * 500 == resumed["timing"]["rollouts_replayed"]
    # the total is a bound: the audit's levels may reach gamma sooner; it
    # counts the rays a search takes in low dimension (X in two here)
    done = monitor.replayed + monitor.simulated
    rays = resumed["estimate"]["details"]["directional"]["n_calls"]
    assert done == resumed["estimate"]["n_evals"] <= monitor.total
    assert monitor.total == CE.total_rollouts + rays


def test_rows_that_failed_in_the_first_chunk_are_replaced_by_others(tmp_path):
    calls = []

    def down_for_the_first_chunk(x):
        calls.append(len(x))
        return failing(x) if len(calls) == 1 else f(x)

    path = tmp_path / "run"
    with pytest.raises(TooManyFailuresError):
        run(path, settings=NAIVE, objective=down_for_the_first_chunk)
    rows = replayed_rows(RunDirectory(path, NAMES))
    assert {batch.chunk for batch, _ in rows} == {1}
    with pytest.raises(NotRepeatableError, match="chunk 1, row"):
        run(path, NAIVE, changed_near_hits, check=changed_near_hits)


def test_a_resume_with_nothing_recorded_that_succeeded_says_so(tmp_path):
    reference = run(tmp_path / "reference", settings=NAIVE)
    path = tmp_path / "run"
    with pytest.raises(TooManyFailuresError):
        run(path, settings=NAIVE, objective=failing)
    with pytest.warns(UncheckedResumeWarning, match="no rollout recorded in"):
        resumed = run(path, settings=NAIVE, check=changed_near_hits)
    assert resumed["estimate"]["by_gamma"] == reference["estimate"]["by_gamma"]


def test_a_resume_whose_replays_all_fail_now_stops(tmp_path):
    path = tmp_path / "run"
    interrupted(path)
    with pytest.raises(NotRepeatableError, match="all failed now: start the ego"):
        run(path, check=failing)


def test_a_changed_chunk_holding_picked_rows_is_left_to_the_run(tmp_path):
    path = tmp_path / "run"
    interrupted(path)
    (lowest, _), *_ = replayed_rows(RunDirectory(path, NAMES))[FIRST_ROWS:]
    chunk = path / "chunks" / f"stage{lowest.stage:04d}-chunk000000.parquet"
    pq.write_table(pq.read_table(chunk), chunk, compression="none")  # other bytes
    with pytest.warns(RecordIntegrityWarning, match="evaluated again"):
        rows = replayed_rows(RunDirectory(path, NAMES))
    assert len(rows) == FIRST_ROWS + LOWEST_ROWS  # picked again, elsewhere
    assert {batch.stage for batch, _ in rows} == {3 - lowest.stage}
    assert not chunk.exists()
