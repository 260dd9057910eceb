"""A resumed run checks the Python ego it resumes with, named by import path.

The change tested: the reference controller braking 10% later
(:class:`~tests.cli.ego_servers.LateBrakingAcc`), an edit of the class
between two sessions (same import path). ``test_external_ego`` tests the same
change of an AV server restarted at the same address.
"""

import json
import re

import pytest
from typer.testing import CliRunner

from avrisk.cli.app import app
from tests.interrupts import ctrl_c_at_chunk
from tests.scenario_files import shortened_scenario

pytest.importorskip("zmq")  # tests.cli.ego_servers needs the external extra

import tests.cli.ego_servers as ego_servers  # noqa: E402
from tests.cli.ego_servers import LateBrakingAcc  # noqa: E402

CE = ("--method", "ce", "--rho", "0.1", "--n-per-iter", "60", "--n-iter", "2")
CE += ("--n-final", "100", "--gamma", "1.0", "--batch-size", "64", "--failures", "0")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """``highway_idm`` cut to 2 s with the reference controller as a Python class."""
    ego = {"policy": "tests.cli.ego_servers:InProcessAcc", "params": {}}
    directory = tmp_path_factory.mktemp("scenario")
    return shortened_scenario(directory, 2.0, file="acc.yaml", name="acc", ego=ego)


def interrupted(monkeypatch, *args):
    """``avrisk run ARGS`` stopped by Ctrl-C once its first chunk is recorded."""
    with ctrl_c_at_chunk(monkeypatch, 2):
        assert invoke("run", *args).exit_code == 130


def test_a_python_ego_edited_between_sessions_is_refused(
    in_process, tmp_path, monkeypatch
):
    out = tmp_path / "run"
    interrupted(monkeypatch, in_process, "--out", out, *CE)
    monkeypatch.setattr(ego_servers, "InProcessAcc", LateBrakingAcc)
    result = invoke("run", in_process, "--out", out, *CE)
    assert result.exit_code == 2
    (line,) = [ln for ln in result.output.splitlines() if "error:" in ln]
    assert (
        "f differs from the run recorded in" in line and "stage 1, chunk 0, row" in line
    )
    assert "resume with the ego the run was recorded with" in line


def test_the_same_python_ego_resumes_to_the_same_estimate(
    in_process, tmp_path, monkeypatch
):
    reference = tmp_path / "reference"
    assert invoke("run", in_process, "--out", reference, *CE).exit_code == 0
    out = tmp_path / "run"
    interrupted(monkeypatch, in_process, "--out", out, *CE)
    result = invoke("run", in_process, "--out", out, *CE)
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    expected = json.loads((reference / "summary.json").read_text())
    assert summary["estimate"]["by_gamma"] == expected["estimate"]["by_gamma"]
    reused, simulated = map(
        int,
        re.search(
            r"resumed: ([\d,]+) rollouts reused from the earlier session, "
            r"([\d,]+) simulated now",
            " ".join(result.stderr.split()),
        ).groups(),
    )
    assert reused == 60 == summary["timing"]["rollouts_replayed"]
    audit = summary["estimate"]["details"]["audit"]["n_calls"]
    assert reused + simulated == summary["estimate"]["n_evals"] == 220 + audit
