"""``avrisk run --workers N``: the numbers of one worker, bit for bit."""

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from avrisk.cli.app import app
from avrisk.rare.parallel import EVALUATED_BY
from tests.scenario_files import shortened_scenario

#: Two chunks (8192 + 8 rollouts) so that two workers share the stage.
NAIVE_ARGS = ("--method", "naive", "--n-final", 8200, "--seed", 4, "--failures", 1)


@pytest.fixture(scope="module")
def tiny_scenario(tmp_path_factory):
    """The bundled highway_idm with a 0.5 s horizon (worker start-up dominates)."""
    directory = tmp_path_factory.mktemp("scenario")
    return shortened_scenario(directory, 0.5, file="tiny.yaml")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def run_table(out):
    table = pq.read_table(out / "samples.parquet")
    summary = json.loads((out / "summary.json").read_text())
    return table, summary["estimate"] | {"wall_time_s": 0}


def test_two_workers_give_the_one_worker_run_bit_for_bit(tiny_scenario, tmp_path):
    runs = {}
    for n in (1, 2):
        out = tmp_path / f"workers{n}"
        result = invoke("run", tiny_scenario, "--out", out, *NAIVE_ARGS, "--workers", n)
        assert result.exit_code == 0, result.output
        runs[n] = run_table(out)
    (one, one_estimate), (two, two_estimate) = runs[1], runs[2]
    assert two_estimate == one_estimate
    assert one.column_names == two.column_names
    for column in set(one.column_names) - {EVALUATED_BY}:
        assert two[column].equals(one[column]), column
    assert len(set(one[EVALUATED_BY].to_pylist())) == 1
    # a chunk goes to the first free worker: on a loaded machine the first may
    # finish both before the second has started
    assert len(set(two[EVALUATED_BY].to_pylist())) in (1, 2)
    assert all(s.startswith("processes ") for s in two[EVALUATED_BY].to_pylist())


@pytest.mark.parametrize(
    "args, message",
    [
        (("--workers", 0), "Invalid value for '--workers'"),
        (("--backend", "foo"), "Invalid value for '--backend'"),
        (
            ("--address", "10.0.0.1:6379"),
            "--address joins a Ray cluster: add --backend",
        ),
    ],
)
def test_bad_backend_options_are_one_clear_line(tiny_scenario, tmp_path, args, message):
    out = tmp_path / "run"
    result = invoke("run", tiny_scenario, "--out", out, *NAIVE_ARGS, *args)
    assert result.exit_code == 2
    assert message in " ".join(result.output.split()).replace("│", "")
    assert "Traceback" not in result.output and not out.exists()


def test_the_ray_backend_without_ray_installed_says_how_to_install_it(
    tiny_scenario, tmp_path, monkeypatch
):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails
    out = tmp_path / "run"
    result = invoke("run", tiny_scenario, "--out", out, *NAIVE_ARGS, "--backend", "ray")
    assert result.exit_code == 2
    assert "the ray backend needs Ray: pip install 'avrisk[ray]'" in result.output
    assert "Traceback" not in result.output and not out.exists()


#: A CE run of seven one-chunk stages: Ctrl-C lands with most of them to come.
CE_ARGS = ("--method", "ce", "--rho", 0.1, "--n-per-iter", 200, "--n-iter", 6)
CE_ARGS += ("--n-final", 400, "--gamma", 0.5, "--failures", 0)


def live_processes(group):
    """Pids of the processes of process group ``group`` that are not zombies.

    From Linux's /proc (empty elsewhere).
    """
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            state, _, pgrp = stat.read_text().rsplit(")", 1)[1].split()[:3]
        except (OSError, ValueError):
            continue  # gone meanwhile
        if int(pgrp) == group and state != "Z":
            pids.append(int(stat.parent.name))
    return pids


def _as_in_a_terminal():
    """Ctrl-C's default action in the child: a shell's background job (``&``,
    ``nohup``) ignores SIGINT, and a child would inherit that."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_avrisk(*args, stderr=subprocess.PIPE):
    """``avrisk ARGS`` in a process group of its own, as a terminal runs it."""
    return subprocess.Popen(
        [sys.executable, "-c", "from avrisk.cli import main; main()", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
        start_new_session=True,
        preexec_fn=_as_in_a_terminal,
        env={**os.environ, "COLUMNS": "80"},
    )


def assert_stopped_cleanly(process, err):
    """Exit status 130, the resume line, no traceback, no process left running."""
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    (line,) = [ln for ln in err.splitlines() if "Resume with: " in ln]
    for _ in range(100):  # the workers are stopped, not left running
        if not live_processes(process.pid):
            break
        time.sleep(0.1)
    assert not live_processes(process.pid)
    return shlex.split(line.split("Resume with: ")[1])


def test_ctrl_c_while_the_command_loads_is_one_line(tiny_scenario, tmp_path):
    """Loading takes seconds (torch): a Ctrl-C then is no traceback either."""
    out = tmp_path / "run"
    process = start_avrisk("run", tiny_scenario, "--out", out, *CE_ARGS, "--workers", 2)
    time.sleep(0.5)
    os.killpg(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    # while loading (on a slow machine), or else the run's own line
    assert "interrupted while loading: nothing was run" in err or "Resume with" in err
    assert not out.exists()


def test_ctrl_c_while_the_workers_start_is_one_line_from_the_parent(
    tiny_scenario, tmp_path
):
    """A terminal's Ctrl-C reaches workers still loading: they never print it."""
    out = tmp_path / "run"
    process = start_avrisk(
        "run", tiny_scenario, "--out", out, *CE_ARGS, "--workers", 2,
        stderr=subprocess.STDOUT,
    )  # fmt: skip
    lines = []
    for line in process.stdout:  # the plan comes just before the workers start
        lines.append(line)
        if line.startswith("plan: "):
            break
    time.sleep(1.0)  # they are importing torch
    os.killpg(process.pid, signal.SIGINT)
    rest, _ = process.communicate(timeout=120)
    assert_stopped_cleanly(process, "".join(lines) + rest)
    assert not out.exists()  # nothing recorded, nothing left


def test_ctrl_c_stops_the_workers_and_the_resumed_run_gives_the_same_estimate(
    tiny_scenario, tmp_path
):
    out = tmp_path / "run"
    process = start_avrisk("run", tiny_scenario, "--out", out, *CE_ARGS, "--workers", 2)
    deadline = time.monotonic() + 300
    while not list((out / "chunks").glob("*.parquet")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "no chunk recorded in 5 minutes"
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGINT)  # Ctrl-C: to every process of the group
    _, err = process.communicate(timeout=120)
    resume = assert_stopped_cleanly(process, err)
    assert resume[:2] == ["avrisk", "run"] and "--workers" in resume
    assert not list(out.rglob("*.tmp-*"))  # no half-written temporary file
    recorded = len(list((out / "chunks").glob("*.parquet")))
    assert 1 <= recorded < 7 and not (out / "summary.json").exists()

    resumed = invoke(*resume[1:])
    assert resumed.exit_code == 0, resumed.output
    reused = f"resumed: {200 * recorded:,} rollouts reused from the earlier session"
    assert reused in " ".join(resumed.stderr.split())
    reference = tmp_path / "uninterrupted"
    assert invoke("run", tiny_scenario, "--out", reference, *CE_ARGS).exit_code == 0
    (_, estimate), (_, expected) = run_table(out), run_table(reference)
    assert estimate == expected


def test_a_ctrl_c_inside_an_extension_s_import_is_an_interruption_too(capsys):
    from avrisk.cli.interrupt import INTERRUPTED, loading

    def extension_import():  # as SciPy's pybind11 modules raise it
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as ctrl_c:
            raise ImportError("initialization failed") from ctrl_c

    with pytest.raises(SystemExit) as stopped, loading():
        extension_import()
    assert stopped.value.code == INTERRUPTED
    assert capsys.readouterr().err == "interrupted while loading: nothing was run\n"
    with pytest.raises(ImportError, match="no module named x"), loading():
        raise ImportError("no module named x")  # a real import failure stays one
