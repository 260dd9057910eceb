"""``avrisk run`` on the vision scenario, end to end (a tiny budget)."""

import json

import pyarrow.parquet as pq
from PIL import Image
from typer.testing import CliRunner

from avrisk.assembly import FAILURES_FILE, read_failure_traces
from avrisk.cli.app import app
from avrisk.pipeline.layout import CONFIG_FILE, SAMPLES_FILE, SUMMARY_FILE
from avrisk.report.animate import animate_rollouts
from avrisk.scenario import load_spec
from tests.scenario_files import shortened_scenario


def test_avrisk_run_estimates_with_the_vision_ego(tmp_path):
    scenario = shortened_scenario(
        tmp_path, 0.5, scenario="highway_vision", name="vision_short"
    )
    out = tmp_path / "run"
    # every rollout counts as a failure at gamma = 100 s: the report animates one
    args = ["run", scenario, "--out", out, "--method", "naive", "--n-final", 6]
    args += ["--gamma", 100, "--gamma-test", 50, "--failures", 1]
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    assert "vision_pilotnet" in (out / CONFIG_FILE).read_text()
    table = pq.read_table(out / SAMPLES_FILE)
    assert table.num_rows == 6 and (table["status"].to_numpy() == 0).all()
    summary = json.loads((out / SUMMARY_FILE).read_text())
    assert summary["method"] == "naive"
    # The failure's animation shows the camera above the top-down view: taller
    # than the top-down view alone of the same recorded rollout.
    (gif,) = (out / "animations").glob("*.gif")
    (trace,) = [t for _, t in read_failure_traces(out / FAILURES_FILE).values()][:1]
    spec = load_spec(scenario)
    top_down = animate_rollouts([trace], spec.road, 0.1, tmp_path / "top.gif")
    with Image.open(gif) as video, Image.open(top_down) as plain:
        assert video.width == plain.width and video.height > plain.height + 80
    report = (out / "report.html").read_text()
    assert gif.name in report and "what the ego's camera saw" in report
