"""Retraining through the API: inputs checked first, the recipe asked, the warnings.

The trainings themselves are stand-ins that write empty files (the real ones
take seconds at their tiniest and are tested in tests/learning and through
the commands); what is tested here is what the API does around them.
"""

import json
import shutil
from types import SimpleNamespace

import pytest

import avrisk.api.training as api_training
import avrisk.learning.training.report as training_report
import avrisk.learning.training.train as training
import avrisk.learning.vision as vision
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.store import default_drivers_dir
from avrisk.api import UserError
from avrisk.api.training import (
    OtherKernelsWarning,
    ShippedFilesWarning,
    retrain_drivers,
    retrain_vision,
    training_config,
)
from avrisk.learning.train_config import TrainConfig

DRIVER_FILES = ["driver_net.npz", "xi_prior.npz", "training_report.json"]


@pytest.fixture
def trainings(monkeypatch):
    """The arguments of each driver or vision training, which writes empty files."""
    calls = []

    def drivers(seed, out, **kwargs):
        calls.append(("drivers", seed, out, kwargs))
        for name in DRIVER_FILES:
            (out / name).write_bytes(b"")
        return SimpleNamespace(selection={"chosen_seed": seed, "candidates": []})

    def pilotnet(seed, out, **kwargs):
        calls.append(("vision", seed, out, kwargs))
        for name in ("pilotnet.npz", "training_report.json"):
            (out / name).write_bytes(b"")
        return {"seed": seed}

    monkeypatch.setattr(training, "train_drivers", drivers)
    monkeypatch.setattr(vision, "train_vision", pilotnet)
    return calls


@pytest.fixture
def same_kernels(monkeypatch):
    """This machine's CPU kernels made those that trained the shipped drivers."""
    report = json.loads((default_drivers_dir() / "training_report.json").read_text())
    theirs = report["environment"]["cpu_kernels"]
    monkeypatch.setattr(training_report, "cpu_kernels", lambda: theirs)
    return theirs


def test_the_recipe_takes_the_brake_and_periods_asked():
    assert training_config() == TrainConfig()
    assert TrainConfig().closed_loop.drive_with_guard
    assert not training_config("none").closed_loop.drive_with_guard
    assert training_config("none").guard is None
    held = training_config("1,3,hold")
    assert held.guard == BrakeGuard(1.0, 3.0, hold_floor=True)
    assert held.closed_loop.drive_with_guard
    assert training_config().periods is None
    assert training_config(None, ["0500pm-0515pm"]).periods == ("0500pm-0515pm",)


def test_the_drivers_are_trained_as_asked_into_the_folder_created(
    tmp_path, fake_ngsim, trainings, same_kernels, recwarn
):
    out = tmp_path / "new" / "drivers"
    trained = retrain_drivers(
        out,
        seed=4,
        data_dir=fake_ngsim,
        brake_guard="none",
        candidates=2,
        workers=2,
        progress=print,
    )
    ((what, seed, where, kwargs),) = trainings
    assert (what, seed, where) == ("drivers", 4, out)
    assert kwargs["data_dir"] == fake_ngsim and kwargs["progress"] is print
    assert (kwargs["candidates"], kwargs["workers"]) == (2, 2)
    assert kwargs["config"] == training_config("none")
    assert trained.folder == out
    assert [p.name for p in trained.files] == DRIVER_FILES
    assert all(p.parent == out and p.is_file() for p in trained.files)
    assert trained.selection == {"chosen_seed": 4, "candidates": []}
    assert not recwarn.list  # neither the shipped folder nor other kernels


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ({"brake_guard": "3"}, "brake guard is GAP_FLOOR,ENGAGE_DECEL"),
        ({"periods": ["0515pm-0530pm"]}, "--period 0515pm-0530pm: the I-80 data"),
        ({"data_dir": "nowhere"}, "does not exist (--data-dir)"),
    ],
)
def test_a_bad_input_is_a_user_error_before_training_or_writing(
    tmp_path, fake_ngsim, trainings, args, needle
):
    args = {"data_dir": fake_ngsim, **args}
    if args["data_dir"] == "nowhere":
        args["data_dir"] = tmp_path / "nowhere"
    out = tmp_path / "drivers"
    with pytest.raises(UserError) as raised:
        retrain_drivers(out, **args)
    assert needle in str(raised.value)
    assert trainings == [] and not out.exists()


def test_damaged_ngsim_data_and_an_unwritable_out_are_user_errors(
    tmp_path, fake_ngsim, trainings
):
    pairs = fake_ngsim / "i80_cf_pairs.csv.gz"
    original = pairs.read_bytes()
    pairs.write_bytes(original[: len(original) // 2])
    with pytest.raises(UserError, match=f"--data-dir: {pairs}: not readable"):
        retrain_drivers(tmp_path / "a", data_dir=fake_ngsim)
    pairs.write_bytes(original)
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(UserError, match="cannot write to --out"):
        retrain_drivers(blocker / "drivers", data_dir=fake_ngsim)
    with pytest.raises(UserError, match="cannot write to --out"):
        retrain_vision(blocker / "vision")
    assert trainings == []


def test_writing_into_the_shipped_folder_warns_that_it_replaces_them(
    tmp_path, fake_ngsim, trainings, same_kernels, monkeypatch
):
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    shutil.copy(default_drivers_dir() / "training_report.json", shipped)
    monkeypatch.setattr(api_training, "default_drivers_dir", lambda: shipped)
    with pytest.warns(ShippedFilesWarning, match="shipped driver model in"):
        retrain_drivers(shipped, data_dir=fake_ngsim)
    monkeypatch.setattr(api_training, "default_vision_dir", lambda: shipped)
    with pytest.warns(ShippedFilesWarning, match="shipped PilotNet in"):
        retrain_vision(shipped)
    assert [call[0] for call in trainings] == ["drivers", "vision"]


def test_other_cpu_kernels_than_the_shipped_files_say_how_to_match(
    tmp_path, fake_ngsim, trainings, same_kernels, monkeypatch
):
    other = {"torch": "AVX512", "blas": ["SkylakeX"]}
    monkeypatch.setattr(training_report, "cpu_kernels", lambda: other)
    with pytest.warns(OtherKernelsWarning) as warned:
        retrain_drivers(tmp_path / "drivers", data_dir=fake_ngsim)
    said = str(warned[0].message)
    assert "torch AVX512, BLAS SkylakeX" in said
    theirs = same_kernels
    assert f"torch {theirs['torch']}, BLAS {', '.join(theirs['blas'])}" in said
    assert "ATEN_CPU_CAPABILITY=avx2 OPENBLAS_CORETYPE=Haswell" in said


def test_the_pilotnet_is_trained_with_the_seed_into_the_folder(
    tmp_path, trainings, recwarn
):
    out = tmp_path / "vision"
    trained = retrain_vision(out, seed=7, progress=print)
    ((what, seed, where, kwargs),) = trainings
    assert (what, seed, where, kwargs) == ("vision", 7, out, {"progress": print})
    assert [p.name for p in trained.files] == ["pilotnet.npz", "training_report.json"]
    assert trained.report == {"seed": 7} and trained.selection is None
    assert not recwarn.list
