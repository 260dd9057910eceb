"""A user's own ego, named by import path in a scenario, through `avrisk run`.

The user writes a ten-line policy (``tests/user_components.py``) and a YAML
file; avrisk runs it with resume and a report, and never imports it on the
authority of a run directory.
"""

from importlib import resources

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

import avrisk.registry
from avrisk.assembly import FAILURES_FILE, read_failure_traces, scenario_typicality
from avrisk.cli.app import app
from avrisk.scenario import load_spec
from tests.scenario_files import shortened_scenario

USER_EGO = "tests.user_components:HoldSpeedEgo"
ARGS = ("--method", "naive", "--n-final", 300, "--gamma", 1.5, "--failures", 2)


@pytest.fixture(scope="module")
def user_scenario(tmp_path_factory):
    return shortened_scenario(
        tmp_path_factory.mktemp("scenario"),
        3.0,
        file="user_ego.yaml",
        name="user_ego",
        ego={"policy": USER_EGO, "params": {"speed": 30.0}},
    )


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_a_user_ego_runs_with_failures_recorded_and_a_report(user_scenario, tmp_path):
    out = tmp_path / "run"
    result = invoke("run", user_scenario, "--out", out, *ARGS)
    assert result.exit_code == 0, result.output
    table = pq.read_table(out / "samples.parquet")
    hits = table.filter(table["f"].to_numpy() <= 1.5)
    assert hits.num_rows >= 2  # dangerous rollouts to show
    recorded = read_failure_traces(out / FAILURES_FILE)
    assert len(recorded) == 2
    # the two the report ranks first (lower percentile of P0, then log p0)
    typical = scenario_typicality(load_spec(user_scenario))
    start = np.stack([hits[c].to_numpy() for c in typical.columns], axis=1)
    best = sorted(map(tuple, typical.rank(start, hits["log_p0"].to_numpy())))[-2:]
    np.testing.assert_allclose(sorted(key for key, _ in recorded.values()), best)
    assert (out / "animations" / "failure_1.gif").is_file()


def test_the_report_of_a_user_ego_run_needs_no_import(
    user_scenario, tmp_path, monkeypatch
):
    out = tmp_path / "run"
    assert invoke("run", user_scenario, "--out", out, *ARGS).exit_code == 0
    (out / "report.html").unlink()
    (out / "animations" / "failure_1.gif").unlink()

    def refuse(*args, **kwargs):
        raise AssertionError("avrisk imported user code for a report")

    monkeypatch.setattr(avrisk.registry.importlib, "import_module", refuse)
    result = invoke("report", out, "--failures", 2)
    assert result.exit_code == 0, result.output
    assert (out / "report.html").is_file()
    assert (out / "animations" / "failure_1.gif").is_file()  # from the record


def test_rerunning_with_the_spec_reads_a_user_ego_run_back(user_scenario, tmp_path):
    out = tmp_path / "run"
    assert invoke("run", user_scenario, "--out", out, *ARGS).exit_code == 0
    first = (out / "summary.json").read_text()
    again = invoke("run", user_scenario, "--out", out, *ARGS)
    assert again.exit_code == 0, again.output
    assert (out / "summary.json").read_text() == first


def test_a_spec_read_back_never_imports_its_import_paths():
    from avrisk.assembly import ScenarioSimulator
    from avrisk.scenario import load_spec, spec_from_dict

    text = resources.files("avrisk.data.scenarios").joinpath("highway_idm.yaml")
    data = yaml.safe_load(text.read_text())
    data["ego"] = {"policy": USER_EGO}
    spec = spec_from_dict(data)
    assert spec.import_paths() == [USER_EGO]
    with pytest.raises(ValueError, match="imports user code only from a scenario"):
        ScenarioSimulator(spec)  # allow_import defaults to False
    assert load_spec("highway_idm").import_paths() == []
