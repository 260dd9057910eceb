"""``avrisk realism`` through the Typer app: the files it writes, and bad input."""

import json
import shutil

import pytest
from PIL import Image
from typer.testing import CliRunner

import avrisk
import avrisk.realism
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import default_drivers_dir, load_driver_net
from avrisk.cli.app import app
from avrisk.fingerprint import sha256_file
from avrisk.realism import FILES, RealismSettings
from tests.cli.test_terminal import assert_whole_at_80_columns

TINY = ("--windows", "3", "--replicates", "1", "--scenes", "1")


def realism(*args):
    return CliRunner().invoke(
        app, ["realism", *[str(a) for a in args]], env={"COLUMNS": "80"}
    )


def test_the_report_is_written_whole_with_its_provenance(
    tmp_path, short_parts, drivers_copy
):
    out = tmp_path / "report"
    result = realism(*TINY, "--seed", "5", "--drivers", drivers_copy, "--out", out)
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == sorted(FILES.values())
    figures = json.loads((out / "realism.json").read_text())
    prov = figures["provenance"]
    assert prov["avrisk"] == avrisk.__version__
    assert prov["drivers"]["shipped"] is False
    assert prov["drivers"]["sha256"] == {
        name: sha256_file(default_drivers_dir() / name)
        for name in ("driver_net.npz", "xi_prior.npz")
    }
    assert prov["settings"] == {
        "seed": 5,
        "replicates": 1,
        "windows": 3,
        "scenes": 1,
        "window_s": 3.0,
        "horizon": 6.0,
        "guard": load_driver_net(drivers_copy / "driver_net.npz").guard.to_dict(),
        "held_out": "test",
    }
    held_out = prov["held_out"]["part_a"]
    assert held_out["windows"] == 3 and len(held_out["indices"]) == 3
    assert held_out["windows_available"] > 3
    assert prov["held_out"]["part_b"]["split_seed"] == 21
    assert "us101_lane_changes.parquet" in prov["data_sha256"]
    assert prov["vehicle_hours"]["part_a_per_model"] == pytest.approx(3 * 3 / 3600)
    assert set(figures["part_a"]["models"]) == {
        "learned mu0",
        "learned xi~P0",
        "learned xi~P0, mean actions",
        "IDM",
    }
    assert len(figures["part_a_targets"]["learned mu0"]) == 8
    assert set(figures["part_a_bands"]) <= {"congested", "flowing"}
    assert "IDM+MOBIL" in figures["part_b"]["models"]
    text = (out / "realism.md").read_text()
    titles = ("**A. Car following", "**Targets of issue 21", "**Part A by held-out")
    for title in (*titles, "**Collisions of "):
        assert title in text
    assert "**B. Lane changes** (1 random six-lane scenes x 6 vehicles x 6 s" in text
    assert "--drivers" in text and "--seed 5" in text
    for name in ("part_a_cdfs.png", "lane_changes.png"):
        with Image.open(out / name) as image:
            assert image.format == "PNG" and image.size[0] > 1000
    assert_whole_at_80_columns(result.stdout)
    assert "Issue 21's targets, part A" in result.stdout
    assert "wrote realism.md, realism.json" in " ".join(result.stdout.split())


def test_the_same_seed_gives_the_same_figures(tmp_path, short_parts):
    runs = []
    for name in ("a", "b"):
        assert realism(*TINY, "--out", tmp_path / name).exit_code == 0
        figures = json.loads((tmp_path / name / "realism.json").read_text())
        runs.append({k: v for k, v in figures.items() if k != "provenance"})
    assert runs[0] == runs[1]


@pytest.mark.slow
def test_the_report_at_the_real_window_and_scene_lengths(tmp_path):
    out = tmp_path / "report"
    result = realism(
        "--windows", "2", "--replicates", "1", "--scenes", "1", "--out", out
    )
    assert result.exit_code == 0, result.output
    figures = json.loads((out / "realism.json").read_text())
    assert figures["part_a"]["window_s"] == 15.0
    assert figures["provenance"]["drivers"]["shipped"] is True
    assert figures["part_b"]["models"]["IDM+MOBIL"]["driven_hours"] == pytest.approx(
        6 * 60.0 / 3600
    )


def one_line_error(result):
    assert result.exit_code == 2, result.output
    assert result.output.count("\n") == 1, result.output
    assert result.output.startswith("error: ")
    return result.output


def test_a_missing_drivers_folder_is_a_one_line_error(tmp_path):
    out = one_line_error(realism("--drivers", tmp_path / "nowhere", "--out", tmp_path))
    assert "no such folder" in out


def test_a_drivers_folder_without_the_prior_is_a_one_line_error(tmp_path, drivers_copy):
    (drivers_copy / "xi_prior.npz").unlink()
    out = one_line_error(realism("--drivers", drivers_copy, "--out", tmp_path / "o"))
    assert "lacks xi_prior.npz" in out
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "name, what",
    [("driver_net.npz", "not a driver network"), ("xi_prior.npz", "not an xi prior")],
)
def test_a_corrupt_driver_file_is_a_one_line_error(tmp_path, drivers_copy, name, what):
    (drivers_copy / name).write_bytes(b"this is not a numpy archive")
    out = one_line_error(realism("--drivers", drivers_copy, "--out", tmp_path / "o"))
    assert what in out and name in out


def test_an_archive_with_the_wrong_arrays_is_a_one_line_error(tmp_path, drivers_copy):
    shutil.copy(drivers_copy / "xi_prior.npz", drivers_copy / "driver_net.npz")
    out = one_line_error(realism("--drivers", drivers_copy, "--out", tmp_path / "o"))
    assert "not a driver network" in out


def test_an_out_path_that_is_a_file_is_refused_before_any_work(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    out = one_line_error(realism("--out", blocker))
    assert "is a file" in out


def test_the_brake_guard_is_used_and_recorded(tmp_path, short_parts):
    out = tmp_path / "report"
    result = realism(*TINY, "--brake-guard", "2,1", "--out", out)
    assert result.exit_code == 0, result.output
    figures = json.loads((out / "realism.json").read_text())
    guard = figures["provenance"]["settings"]["guard"]
    assert guard == {"gap_floor": 2.0, "engage_decel": 1.0}
    assert "with an emergency brake (gap floor 2 m" in (out / "realism.md").read_text()


def test_by_default_the_drivers_own_brake_is_used_and_none_turns_it_off(
    tmp_path, short_parts, drivers_copy
):
    net = DriverNet.load(drivers_copy / "driver_net.npz")
    net.guard = BrakeGuard(4.0, 0.25)
    net.save(drivers_copy / "driver_net.npz")
    runs = {"own": (), "off": ("--brake-guard", "none")}
    for name, option in runs.items():
        out = tmp_path / name
        result = realism(*TINY, "--drivers", drivers_copy, *option, "--out", out)
        assert result.exit_code == 0, result.output
        runs[name] = json.loads((out / "realism.json").read_text())
        runs[name]["md"] = (out / "realism.md").read_text()
    own = runs["own"]["provenance"]["settings"]["guard"]
    assert own == {"gap_floor": 4.0, "engage_decel": 0.25}
    assert "gap floor 4 m" in runs["own"]["md"]
    assert runs["off"]["provenance"]["settings"]["guard"] is None
    assert "emergency brake" not in runs["off"]["md"]


@pytest.mark.parametrize("text", ["2", "a,b", "2,1,3", "-1,1", "2,0", "inf,1"])
def test_a_bad_brake_guard_is_a_one_line_error_before_any_work(tmp_path, text):
    out = one_line_error(realism("--brake-guard", text, "--out", tmp_path / "r"))
    assert "gap" in out.lower() or "decel" in out.lower()
    assert not (tmp_path / "r").exists()


def test_settings_refuse_a_guard_they_cannot_drive_with():
    with pytest.raises(ValueError, match="guard must be"):
        RealismSettings(guard="3,0.5")
