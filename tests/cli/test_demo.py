import json

from typer.testing import CliRunner

import avrisk
from avrisk.cli.app import app


def test_demo_prints_both_estimators_and_writes_json(tmp_path):
    out = tmp_path / "demo.json"
    args = [
        "demo",
        "--budget",
        "50000",
        "--seed",
        "3",
        "--out",
        str(out),
        "--rollouts",
        "0",
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "naive MC" in result.output and "CE" in result.output
    data = json.loads(out.read_text())
    for problem in data.values():
        ce = problem["cross_entropy"]
        assert ce["n_evals"] == 50000
        assert abs(ce["p"] - problem["p_exact"]) < 5 * ce["stderr"]


def test_version_option_prints_the_version():
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and avrisk.__version__ in result.output


def test_demo_rejects_a_budget_below_its_minimum():
    result = CliRunner().invoke(app, ["demo", "--budget", "10"])
    assert result.exit_code != 0
    assert "budget" in result.output
