"""``avrisk simulate`` and ``avrisk replay`` through the Typer app."""

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from avrisk.api.rollouts import META_RUN
from avrisk.cli.app import app
from avrisk.scenario import ParamLayout, load_spec

runner = CliRunner()


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory) -> Path:
    """The default scenario cut to 2 s and 36 TTC rays, to keep tests fast."""
    data = load_spec("highway_idm").model_dump(mode="json")
    data["simulation"]["horizon"] = 2.0
    data["safety"]["n_rays"] = 36
    path = tmp_path_factory.mktemp("scen") / "short.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _simulate(*args: str):
    return runner.invoke(app, ["simulate", *args])


def test_simulate_writes_one_row_per_rollout_with_named_columns(
    short_scenario, tmp_path
):
    out = tmp_path / "rollouts.parquet"
    result = _simulate(
        str(short_scenario), "--n", "12", "--seed", "3", "--out", str(out)
    )
    assert result.exit_code == 0, result.output
    table = pq.read_table(out)
    layout = ParamLayout(n_vehicles=6)
    expected = [
        "phase",
        "stage",
        "iteration",
        "chunk",
        "sample_id",
        "seed",
        *layout.columns,
        "log_p0",
        "log_p_proposal",
        "log_weight",
        "weight",
        "f",
        "crash",
        "offroad",
        "reversing",
        "steps",
        "status",
        "collision_with",
        "contact",
    ]
    assert table.column_names == expected
    assert table.num_rows == 12
    assert table.column("sample_id").to_pylist() == list(range(12))
    assert table.schema.field("veh3.speed").metadata == {b"unit": b"m/s"}
    assert table.schema.field("f").metadata == {b"unit": b"s"}
    assert np.isfinite(table.column("log_p0").to_numpy()).all()
    steps = table.column("steps").to_numpy()
    assert ((steps >= 1) & (steps <= 20)).all()
    assert "min TTC <= 0.2 s" in result.output and "crash" in result.output


def test_the_same_seed_gives_the_same_rows_whatever_the_batch_size(
    short_scenario, tmp_path
):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    common = [str(short_scenario), "--n", "5", "--seed", "4"]
    assert _simulate(*common, "--out", str(a), "--batch-size", "5").exit_code == 0
    assert _simulate(*common, "--out", str(b), "--batch-size", "2").exit_code == 0
    ta, tb = pq.read_table(a), pq.read_table(b)
    assert ta.equals(tb)
    assert len(set(ta.column("seed").to_pylist())) == 5


def test_an_unknown_scenario_is_a_clear_error_without_a_traceback(tmp_path):
    out = tmp_path / "x.parquet"
    result = _simulate("no_such_scenario.yaml", "--n", "2", "--out", str(out))
    assert result.exit_code == 2
    assert "no scenario file" in result.output and "Traceback" not in result.output
    assert not out.exists()


def test_an_invalid_field_is_named_in_the_error(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nvehicles: [{lane: 9}]\n")
    result = _simulate(str(bad), "--n", "2", "--out", str(tmp_path / "x.parquet"))
    assert result.exit_code == 2
    assert "vehicles.0.lane" in result.output and "Traceback" not in result.output


def test_a_missing_output_folder_is_a_clear_error(short_scenario, tmp_path):
    out = tmp_path / "nope" / "x.parquet"
    result = _simulate(str(short_scenario), "--n", "2", "--out", str(out))
    assert result.exit_code == 2 and "does not exist" in result.output


def test_a_failing_run_leaves_no_output_file(short_scenario, tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pq, "write_table", boom)
    out = tmp_path / "x.parquet"
    result = _simulate(str(short_scenario), "--n", "2", "--out", str(out))
    assert result.exit_code != 0
    assert list(tmp_path.iterdir()) == []


def test_replay_resimulates_rows_and_writes_a_gif_and_a_png(short_scenario, tmp_path):
    table_path = tmp_path / "r.parquet"
    assert (
        _simulate(str(short_scenario), "--n", "4", "--out", str(table_path)).exit_code
        == 0
    )
    gif, png = tmp_path / "anim.gif", tmp_path / "frame.png"
    result = runner.invoke(
        app,
        [
            "replay",
            str(table_path),
            "--rows",
            "0,2",
            "--out",
            str(gif),
            "--frame-png",
            str(png),
            "--fps",
            "5",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "warning" not in result.output
    with Image.open(gif) as im:
        # At most 2 s at 5 frames/s plus the first frame (fewer after a crash).
        assert im.format == "GIF" and 2 <= im.n_frames <= 11
    with Image.open(png) as im:
        assert im.format == "PNG"
    worst = tmp_path / "worst.gif"
    result = runner.invoke(
        app,
        ["replay", str(table_path), "--worst", "1", "--out", str(worst), "--fps", "2"],
    )
    assert result.exit_code == 0 and worst.exists()


def test_replay_rejects_rows_out_of_range(short_scenario, tmp_path):
    table_path = tmp_path / "r.parquet"
    assert (
        _simulate(str(short_scenario), "--n", "2", "--out", str(table_path)).exit_code
        == 0
    )
    result = runner.invoke(
        app,
        ["replay", str(table_path), "--rows", "5", "--out", str(tmp_path / "a.gif")],
    )
    assert result.exit_code == 2 and "out of range" in result.output


def test_simulate_and_a_naive_run_write_the_same_rows(short_scenario, tmp_path):
    out = tmp_path / "rollouts.parquet"
    assert _simulate(str(short_scenario), "--n", "40", "--out", str(out)).exit_code == 0
    run_dir = tmp_path / "run"
    args = ["run", str(short_scenario), "--out", str(run_dir), "--method", "naive"]
    args += ["--n-final", "40", "--seed", "0", "--failures", "0"]
    assert runner.invoke(app, args).exit_code == 0
    simulated = pq.read_table(out)
    run = pq.read_table(run_dir / "samples.parquet")
    assert simulated.column_names == run.column_names
    assert simulated.to_pylist() == run.to_pylist()


def test_replay_takes_a_run_directory(short_scenario, tmp_path):
    run_dir = tmp_path / "run"
    args = ["run", str(short_scenario), "--out", str(run_dir), "--method", "naive"]
    args += ["--n-final", "30", "--failures", "0"]
    assert runner.invoke(app, args).exit_code == 0
    gif = tmp_path / "worst.gif"
    result = runner.invoke(
        app, ["replay", str(run_dir), "--worst", "1", "--out", str(gif)]
    )
    assert result.exit_code == 0, result.output
    assert gif.is_file() and "warning" not in result.output


@pytest.fixture(scope="module")
def short_learned_scenario(tmp_path_factory) -> Path:
    """``highway_default`` (learned traffic, 428-d X) cut to 1 s and 36 rays."""
    data = load_spec("highway_default").model_dump(mode="json")
    data["simulation"]["horizon"] = 1.0
    data["safety"]["n_rays"] = 36
    path = tmp_path_factory.mktemp("scen") / "short_learned.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_run_leaves_xi_out_and_replay_draws_it_again(
    short_learned_scenario, tmp_path
):
    args = ["run", str(short_learned_scenario), "--method", "naive"]
    args += ["--n-final", "30", "--failures", "0"]
    for name, extra in (("compact", []), ("full", ["--store-full-samples"])):
        result = runner.invoke(app, [*args, "--out", str(tmp_path / name), *extra])
        assert result.exit_code == 0, result.output
    compact = pq.read_schema(tmp_path / "compact" / "samples.parquet").names
    full = pq.read_schema(tmp_path / "full" / "samples.parquet")
    assert "xi.0" not in compact and "veh1.s" in compact and "xi.403" in full.names
    gif = tmp_path / "worst.gif"
    result = runner.invoke(
        app, ["replay", str(tmp_path / "compact"), "--worst", "1", "--out", str(gif)]
    )
    assert result.exit_code == 0, result.output
    assert gif.is_file() and "warning" not in result.output
    result = runner.invoke(app, ["report", str(tmp_path / "compact")])
    assert result.exit_code == 0, result.output  # left-out xi is not "missing"


@pytest.mark.parametrize("command", ["simulate", "run"])
def test_a_device_that_is_not_there_is_one_line_of_error(command, tmp_path):
    import torch

    bad = ["foo"] + ([] if torch.cuda.is_available() else ["cuda"])
    for device in bad:
        out = tmp_path / ("x.parquet" if command == "simulate" else "run")
        result = runner.invoke(
            app, [command, "highway_idm", "--device", device, "--out", str(out)]
        )
        assert result.exit_code == 2, result.output
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --device")
        assert "Traceback" not in result.output and not out.exists()


def test_device_auto_picks_cuda_when_present_and_is_recorded(short_scenario, tmp_path):
    import json

    import torch

    out = tmp_path / "rollouts.parquet"
    result = _simulate(
        str(short_scenario), "--n", "2", "--device", "auto", "--out", str(out)
    )
    assert result.exit_code == 0, result.output
    meta = json.loads(pq.read_schema(out).metadata[META_RUN])
    assert meta["device"] == ("cuda" if torch.cuda.is_available() else "cpu")


def test_simulate_and_replay_write_under_runs_by_default(
    short_scenario, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    result = _simulate(str(short_scenario), "--n", "4")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "runs" / "rollouts.parquet").is_file()
    replayed = runner.invoke(app, ["replay", "runs/rollouts.parquet", "--rows", "0"])
    assert replayed.exit_code == 0, replayed.output
    assert (tmp_path / "runs" / "replay.gif").is_file()
    assert not list(tmp_path.glob("*.gif")) and not list(tmp_path.glob("*.parquet"))


def test_replay_takes_the_samples_of_a_run_without_its_scenario(
    short_scenario, tmp_path
):
    compared = tmp_path / "cmp"
    args = ["compare", str(short_scenario), "--out", str(compared), "--failures", "0"]
    args += ["--method", "ce", "--n-per-iter", "20", "--n-iter", "1", "--n-final", "20"]
    args += ["--reference-n", "0", "--gamma", "1.0", "--gamma-test", ""]
    assert runner.invoke(app, args).exit_code == 0
    samples = compared / "naive" / "samples.parquet"
    gif = tmp_path / "w.gif"
    result = runner.invoke(
        app, ["replay", str(samples), "--worst", "1", "--out", str(gif)]
    )
    assert result.exit_code == 0, result.output
    assert gif.is_file()
    # the comparison itself holds no samples: one line naming a run to give
    whole = runner.invoke(app, ["replay", str(compared), "--worst", "1"])
    assert whole.exit_code == 2
    assert "a comparison: give one of its runs, e.g." in whole.output
    assert str(compared / "ce") in whole.output
