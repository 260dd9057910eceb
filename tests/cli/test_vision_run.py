"""``avrisk run`` on the vision scenario, end to end (a tiny budget)."""

import json

import pyarrow.parquet as pq
from typer.testing import CliRunner

from avrisk.cli.app import app
from avrisk.pipeline.store import CONFIG_FILE, SAMPLES_FILE, SUMMARY_FILE
from tests.scenario_files import shortened_scenario


def test_avrisk_run_estimates_with_the_vision_ego(tmp_path):
    scenario = shortened_scenario(
        tmp_path, 0.5, scenario="highway_vision", name="vision_short"
    )
    out = tmp_path / "run"
    args = ["run", scenario, "--out", out, "--method", "naive", "--n-final", 6]
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    assert "vision_pilotnet" in (out / CONFIG_FILE).read_text()
    table = pq.read_table(out / SAMPLES_FILE)
    assert table.num_rows == 6 and (table["status"].to_numpy() == 0).all()
    summary = json.loads((out / SUMMARY_FILE).read_text())
    assert summary["method"] == "naive"
