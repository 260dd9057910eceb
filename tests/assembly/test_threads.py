"""torch's threads fitted to the idle cores, unless the user chose a count."""

import pytest
import torch

from avrisk.api.backends import open_evaluator
from avrisk.assembly import threads
from avrisk.assembly.threads import (
    USER_SETTING,
    idle_cores,
    parse_proc_stat,
    threads_fitted_to_load,
)

PROC_STAT = """\
cpu  100 5 20 800 10 1 2 3 40 0
cpu0 50 2 10 400 5 0 1 2 20 0
cpu1 50 3 10 400 5 1 1 1 20 0
intr 12345 0 0
ctxt 999
"""


@pytest.fixture
def two_threads(monkeypatch):
    """torch at two intra-op threads, no user setting; restored after."""
    monkeypatch.delenv(USER_SETTING, raising=False)
    previous = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(previous)


def idle(monkeypatch, cores):
    monkeypatch.setattr(threads, "idle_cores", lambda window_s=0: cores)


def test_proc_stat_gives_all_and_idle_time_and_the_cpus():
    # user..steal (8 columns; guest is inside user); idle + iowait
    assert parse_proc_stat(PROC_STAT) == (941, 810, 2)
    assert parse_proc_stat("intr 1 2\n") is None


def test_idle_cores_is_the_idle_share_of_the_window_times_the_cpus(monkeypatch):
    readings = iter([(1000, 500, 4), (1400, 600, 4)])
    monkeypatch.setattr(threads, "_cpu_times", lambda: next(readings))
    assert idle_cores(window_s=0) == pytest.approx(4 * 100 / 400)
    monkeypatch.setattr(threads, "_cpu_times", lambda: None)
    assert idle_cores(window_s=0) is None


@pytest.mark.parametrize(("cores", "expected"), [(0.0, 1), (1.2, 1), (1.7, 2), (6, 2)])
def test_threads_follow_the_idle_cores_within_one_and_torch_s_count(
    two_threads, monkeypatch, cores, expected
):
    idle(monkeypatch, cores)
    with threads_fitted_to_load() as count:
        assert count == expected == torch.get_num_threads()
    assert torch.get_num_threads() == 2


def test_threads_stay_where_idle_cores_cannot_be_measured(two_threads, monkeypatch):
    idle(monkeypatch, None)
    with threads_fitted_to_load() as count:
        assert count == 2 == torch.get_num_threads()


def test_a_user_s_omp_num_threads_wins(two_threads, monkeypatch):
    monkeypatch.setenv(USER_SETTING, "2")
    idle(monkeypatch, 0.0)
    with threads_fitted_to_load() as count:
        assert count == 2 == torch.get_num_threads()


def test_a_run_in_this_process_simulates_on_the_fitted_threads(
    two_threads, monkeypatch
):
    idle(monkeypatch, 0.0)
    with open_evaluator(None, "local", None, None) as evaluator:
        assert evaluator is None
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    monkeypatch.setenv(USER_SETTING, "2")
    with open_evaluator(None, "local", None, None):
        assert torch.get_num_threads() == 2
