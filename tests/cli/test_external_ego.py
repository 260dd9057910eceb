"""The external ego over ZeroMQ, end to end through ``avrisk run``.

Reference AV servers in Python (``avrisk serve-ego``) and C++
(``examples/ego_server_cpp``) give the same samples as the same controller
in process; faulty servers give failed rollouts with a reason, a bracket or a
clear stop, and a rerun after the AV restarts retries them. Every socket is on
127.0.0.1.
"""

import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

pytest.importorskip("zmq")

from avrisk.cli.app import app  # noqa: E402
from avrisk.pipeline.repeatability import check_repeatable  # noqa: E402
from tests.cli.ego_servers import (  # noqa: E402
    FaultyServer,
    LateBrakingController,
    in_thread,
)
from tests.scenario_files import shortened_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ARGS = ("--method", "naive", "--n-final", 200, "--batch-size", 50, "--failures", 0)
TIMEOUT_S = 0.5
#: What a resume with an AV that changed since says.
CHANGED = "f differs from the run recorded in"


def free_address():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def scenario(tmp_path, ego, name="external"):
    return shortened_scenario(tmp_path, 2.0, file=f"{name}.yaml", name=name, ego=ego)


def external(tmp_path, address):
    ego = {"policy": "external", "params": {"address": address, "timeout_s": TIMEOUT_S}}
    return scenario(tmp_path, ego)


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def samples(out):
    return pq.read_table(out / "samples.parquet")


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The reference controller in process: the samples to match (noise 0.3)."""
    tmp = tmp_path_factory.mktemp("in_process")
    ego = {"policy": "tests.cli.ego_servers:InProcessAcc", "params": {}}
    runs = {}
    for noise in (0.0, 0.3):
        ego["params"]["noise"] = noise
        path = scenario(tmp, ego, name=f"acc{int(noise * 10)}")
        out = tmp / f"run{noise}"
        result = invoke("run", path, "--out", out, *ARGS)
        assert result.exit_code == 0, result.output
        runs[noise] = samples(out)
    return runs


def process(*command):
    proc = subprocess.Popen(
        [str(c) for c in command], stdout=subprocess.PIPE, text=True, cwd=ROOT
    )
    assert "serving" in proc.stdout.readline()
    return proc


def stop(proc):
    proc.kill()
    proc.wait()


def assert_same_rollouts(table, reference):
    assert np.all(table["status"].to_numpy() == 0)
    assert set(table["failure"].to_pylist()) == {""}
    assert np.array_equal(table["f"].to_numpy(), reference["f"].to_numpy())


def test_the_python_server_gives_the_in_process_samples(tmp_path, in_process):
    address = free_address()
    server = process(
        sys.executable, "-c", "from avrisk.cli import main; main()",
        "serve-ego", "--address", address, "--noise", 0.3,
    )  # fmt: skip
    try:
        out = tmp_path / "run"
        result = invoke("run", external(tmp_path, address), "--out", out, *ARGS)
        assert result.exit_code == 0, result.output
        assert_same_rollouts(samples(out), in_process[0.3])
        listening = subprocess.run(["ss", "-tln"], capture_output=True, text=True)
        port = address.rsplit(":", 1)[1]
        assert f"127.0.0.1:{port}" in listening.stdout
    finally:
        stop(server)


@pytest.fixture(scope="module")
def cpp_server(tmp_path_factory):
    """The C++ reference server, built here (skipped, saying why, without tools)."""
    missing = [t for t in ("g++", "make") if shutil.which(t) is None]
    missing += [
        h for h in ("zmq.h", "msgpuck.h") if not Path("/usr/include", h).exists()
    ]
    if missing:
        pytest.skip(
            f"C++ reference server not built: {', '.join(missing)} missing "
            "(apt-get install g++ make libzmq3-dev libmsgpuck-dev; .ci/run does)"
        )
    build = tmp_path_factory.mktemp("cpp")
    subprocess.run(
        ["make", "-C", ROOT / "examples/ego_server_cpp", f"BUILD={build}"],
        check=True,
        capture_output=True,
    )
    return build / "ego_server"


def test_the_cpp_server_gives_the_in_process_samples(tmp_path, cpp_server, in_process):
    address = free_address()
    server = process(cpp_server, address)
    try:
        out = tmp_path / "run"
        result = invoke("run", external(tmp_path, address), "--out", out, *ARGS)
        assert result.exit_code == 0, result.output
        assert_same_rollouts(samples(out), in_process[0.0])
    finally:
        stop(server)


@pytest.mark.parametrize(
    ("mode", "reason"),
    [
        ("sleep", "no reply to step within 0.5 s"),
        ("garbage", "not a msgpack message"),
        ("shape", "accel: shape [51], expected [50]"),
        ("oversized", "over the"),
        ("error", "the AV reported an error: 'planner crashed'"),
    ],
)
def test_a_faulty_batch_fails_its_rollouts_and_stops_the_run(tmp_path, mode, reason):
    address = free_address()
    out = tmp_path / "run"
    with in_thread(FaultyServer(mode, TIMEOUT_S), address):
        result = invoke("run", external(tmp_path, address), "--out", out, *ARGS)
    assert result.exit_code != 0
    assert "50 of 200 samples of stage 0 failed to evaluate" in result.output
    (chunk,) = (out / "chunks").glob("*.parquet")
    table = pq.read_table(chunk)
    failed = table["status"].to_numpy() != 0
    assert failed.sum() == 50 and not np.isnan(table["f"].to_numpy()[~failed]).any()
    reasons = set(np.asarray(table["failure"].to_pylist(), dtype=object)[failed])
    assert len(reasons) == 1 and reason in reasons.pop()


def test_an_av_dying_mid_stage_is_retried_after_its_restart(tmp_path, in_process):
    address = free_address()
    path = external(tmp_path, address)
    out = tmp_path / "run"
    dying = process(sys.executable, ROOT / "tests/cli/ego_servers.py", address, "die")
    try:
        result = invoke("run", path, "--out", out, *ARGS)
    finally:
        stop(dying)
    assert result.exit_code != 0
    assert "150 of 200 samples of stage 0 failed" in result.output
    assert not (out / "samples.parquet").exists()
    with in_thread(FaultyServer("none"), address):
        again = invoke("run", path, "--out", out, *ARGS)
    assert again.exit_code == 0, again.output
    assert_same_rollouts(samples(out), in_process[0.0])


def test_a_nan_action_fails_one_rollout_p_is_bracketed_then_retried(
    tmp_path, in_process
):
    address = free_address()
    path = external(tmp_path, address)
    out = tmp_path / "run"
    with in_thread(FaultyServer("nan", TIMEOUT_S), address):
        result = invoke("run", path, "--out", out, *ARGS, "--gamma", 1.0)
    assert result.exit_code == 0, result.output
    assert "1 rollouts failed to evaluate" in result.output
    table = samples(out)
    assert table["status"].to_numpy().sum() == 1
    assert "non-finite action from the AV" in "".join(table["failure"].to_pylist())
    with in_thread(FaultyServer("none"), address):
        again = invoke("run", path, "--out", out, *ARGS, "--gamma", 1.0)
    assert again.exit_code == 0, again.output
    assert "failed to evaluate" not in again.output
    assert_same_rollouts(samples(out), in_process[0.0])


def test_an_av_that_ignores_its_seeds_is_refused(tmp_path):
    address = free_address()
    out = tmp_path / "run"
    with in_thread(FaultyServer("unrepeatable"), address):
        result = invoke("run", external(tmp_path, address), "--out", out, *ARGS)
    assert result.exit_code != 0
    assert "f is not repeatable" in result.output
    assert not out.exists()


@pytest.fixture
def checked(monkeypatch):
    """Each run's directory and whether it checks fresh draws (the checks run)."""
    found = {}

    def spy(run_dir, base, check, seed):
        found[run_dir.path.name] = check.fresh
        return check_repeatable(run_dir, base, check, seed)

    monkeypatch.setattr("avrisk.pipeline.run.check_repeatable", spy)
    return found


def test_only_new_runs_of_egos_that_may_not_be_repeatable_replay_fresh_draws(
    tmp_path, checked
):
    for name in ("InProcessAcc", "UnvouchedAcc"):
        ego = {"policy": f"tests.cli.ego_servers:{name}"}
        path = scenario(tmp_path, ego, name=name)
        result = invoke("run", path, "--out", tmp_path / name, *ARGS)
        assert result.exit_code == 0, result.output
    address = free_address()
    with in_thread(FaultyServer("none"), address):
        out = tmp_path / "external"
        result = invoke("run", external(tmp_path, address), "--out", out, *ARGS)
    assert result.exit_code == 0, result.output
    assert checked == {"InProcessAcc": False, "UnvouchedAcc": True, "external": True}


def test_an_av_braking_later_after_a_restart_is_refused(tmp_path):
    address = free_address()
    path = external(tmp_path, address)
    out = tmp_path / "run"
    with in_thread(FaultyServer("sleep", TIMEOUT_S), address):
        assert invoke("run", path, "--out", out, *ARGS).exit_code != 0
    later = FaultyServer("none", controller=LateBrakingController())
    with in_thread(later, address):
        result = invoke("run", path, "--out", out, *ARGS)
    assert result.exit_code == 2
    assert CHANGED in result.output


def test_an_av_braking_later_is_refused_after_a_first_chunk_that_all_failed(
    tmp_path,
):
    """The AV was down for the whole first chunk and up for the second."""
    address = free_address()
    path = external(tmp_path, address)
    out = tmp_path / "run"
    two_chunks = ("--method", "naive", "--n-final", 8192 + 50, "--batch-size", 8192)
    down = FaultyServer("error", TIMEOUT_S, batch=3)  # after the check's two
    with in_thread(down, address):
        first = invoke("run", path, "--out", out, *two_chunks, "--failures", 0)
    assert "8192 of 8242 samples of stage 0 failed" in " ".join(first.output.split())
    later = FaultyServer("none", controller=LateBrakingController())
    with in_thread(later, address):
        result = invoke("run", path, "--out", out, *two_chunks, "--failures", 0)
    assert result.exit_code == 2
    assert CHANGED in result.output and "chunk 1, row" in result.output


def test_a_remote_address_is_refused_unless_allowed(tmp_path):
    ego = {"policy": "external", "params": {"address": "tcp://192.0.2.1:5555"}}
    result = invoke("run", scenario(tmp_path, ego), "--out", tmp_path / "r", *ARGS)
    assert result.exit_code == 2
    assert "set allow_remote: true" in result.output
