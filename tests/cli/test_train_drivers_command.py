"""``avrisk train-drivers`` through the Typer app."""

import json
from dataclasses import replace

import pytest
from typer.testing import CliRunner

import avrisk.learning.training.train as training
from avrisk.agents.drivers import XiPrior, load_driver_net
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.store import default_drivers_dir
from avrisk.cli.app import app

runner = CliRunner()


def _train(*args):
    return runner.invoke(app, ["train-drivers", *args])


def tiny_training(monkeypatch, tiny):
    """Train the tiny recipe, with the brake the command line asks for."""
    real = training.train_drivers

    def train(*args, config, **kwargs):
        closed_loop = replace(
            tiny.closed_loop, drive_with_guard=config.closed_loop.drive_with_guard
        )
        asked = replace(tiny, guard=config.guard, closed_loop=closed_loop)
        return real(*args, config=asked, **kwargs)

    monkeypatch.setattr(training, "train_drivers", train)


@pytest.mark.slow
def test_train_drivers_writes_the_model_files_and_names_them(
    tmp_path, fake_ngsim, tiny_train_config, monkeypatch
):
    shipped = {p.name: p.stat().st_mtime_ns for p in default_drivers_dir().iterdir()}
    tiny_training(monkeypatch, tiny_train_config)
    out = tmp_path / "new" / "drivers"
    result = _train("--seed", "2", "--out", str(out), "--data-dir", str(fake_ngsim))
    assert result.exit_code == 0, result.output
    net = load_driver_net(out / "driver_net.npz")
    assert net.default_xi.shape == (404,)
    assert XiPrior.load(out / "xi_prior.npz").members.shape == (3, 404)
    assert json.loads((out / "training_report.json").read_text())["seed"] == 2
    for name in ("driver_net.npz", "xi_prior.npz", "training_report.json"):
        assert name in result.output
    assert "kB" in result.output and "wrote" in result.output
    stages = ("behaviour cloning", "DAgger rounds", "closed-loop training", "xi prior")
    for stage in stages:
        assert stage in result.output
    assert "val/loss=" in result.output
    after = {p.name: p.stat().st_mtime_ns for p in default_drivers_dir().iterdir()}
    assert after == shipped
    # the default brake is written
    assert net.guard == BrakeGuard(2.0, 2.0, hold_floor=True)


@pytest.mark.slow
def test_the_brake_written_with_the_weights_is_chosen_on_the_command_line(
    tmp_path, fake_ngsim, tiny_train_config, monkeypatch
):
    tiny_training(monkeypatch, tiny_train_config)
    data = ("--data-dir", str(fake_ngsim))
    for text, guard in (("none", None), ("2,1", BrakeGuard(2.0, 1.0))):
        out = tmp_path / text
        result = _train("--out", str(out), *data, "--brake-guard", text)
        assert result.exit_code == 0, result.output
        assert load_driver_net(out / "driver_net.npz").guard == guard


@pytest.mark.parametrize("text", ["3", "x,1", "-1,0.5"])
def test_a_bad_brake_is_a_one_line_error_before_training(tmp_path, text):
    result = _train("--brake-guard", text, "--out", str(tmp_path / "d"))
    assert result.exit_code == 2, result.output  # a usage error
    assert result.output.startswith("error: ") and "gap" in result.output.lower()
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


def test_a_missing_data_folder_is_a_one_line_error(tmp_path):
    result = _train("--data-dir", str(tmp_path / "nowhere"), "--out", str(tmp_path))
    assert result.exit_code == 2 and result.output.count("\n") == 1
    assert "error: NGSIM folder" in result.output and "does not exist" in result.output


def test_a_data_folder_without_the_ngsim_files_is_a_one_line_error(tmp_path):
    result = _train("--data-dir", str(tmp_path), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2
    assert "lacks i80_cf_pairs.csv.gz" in result.output
    assert not (tmp_path / "out").exists()


def test_an_out_path_that_cannot_be_a_folder_is_refused_before_training(
    tmp_path, fake_ngsim
):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    result = _train("--data-dir", str(fake_ngsim), "--out", str(blocker / "drivers"))
    assert result.exit_code == 2 and result.output.count("\n") == 1
    assert "error: cannot write to --out" in result.output


@pytest.mark.slow
def test_candidates_print_their_validation_crashes_and_the_one_kept(
    tmp_path, fake_ngsim, tiny_train_config, monkeypatch
):
    tiny_training(monkeypatch, tiny_train_config)
    out = tmp_path / "drivers"
    args = ("--seed", "5", "--out", str(out), "--data-dir", str(fake_ngsim))
    result = _train(*args, "--candidates", "2", "--workers", "2")
    assert result.exit_code == 0, result.output
    assert "Candidates: crashes on their own validation windows" in result.output
    rows = [line.split() for line in result.output.splitlines()]
    assert sum(row[-1:] == ["kept"] for row in rows) == 1  # one row marked
    kept = json.loads((out / "training_report.json").read_text())["seed"]
    assert kept in (5, 6) and (out / "candidates" / f"seed-{kept}").is_dir()


def test_fewer_than_one_candidate_is_refused(tmp_path):
    result = _train("--candidates", "0", "--out", str(tmp_path))
    assert result.exit_code == 2 and "--candidates" in result.output


def test_an_unknown_period_is_a_one_line_error(tmp_path):
    result = _train("--period", "0515pm-0530pm", "--out", str(tmp_path / "d"))
    assert result.exit_code != 0
    assert result.output.startswith("error: ") and "0400pm-0415pm" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


def test_an_unknown_head_is_a_one_line_error_before_training(tmp_path):
    result = _train("--head", "mlp", "--out", str(tmp_path / "d"))
    assert result.exit_code == 2, result.output  # a usage error
    assert result.output.startswith("error: ") and "free, idm" in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


@pytest.mark.slow
def test_the_idm_head_is_chosen_on_the_command_line(
    tmp_path, fake_ngsim, tiny_train_config, monkeypatch
):
    real = training.train_drivers

    def train(*args, config, **kwargs):
        return real(
            *args, config=replace(tiny_train_config, head=config.head), **kwargs
        )

    monkeypatch.setattr(training, "train_drivers", train)
    out = tmp_path / "idm"
    result = _train("--out", str(out), "--data-dir", str(fake_ngsim), "--head", "idm")
    assert result.exit_code == 0, result.output
    assert load_driver_net(out / "driver_net.npz").head_kind == "idm"
