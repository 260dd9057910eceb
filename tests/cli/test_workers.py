"""``avrisk run --workers N``: the numbers of one worker, bit for bit."""

import json
import sys

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
    assert len(set(two[EVALUATED_BY].to_pylist())) == 2  # one chunk each
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
