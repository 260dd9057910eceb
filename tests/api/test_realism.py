"""The realism report through the API: the files, the progress, bad input, warnings."""

import json

import pytest

import avrisk.realism
from avrisk.api import UserError
from avrisk.api.realism import NotHeldOutWarning, realism_report
from avrisk.realism import FILES

TINY = {"windows": 3, "replicates": 1, "scenes": 1}


class Stop(Exception):
    """Raised in place of the parts: the checks before them are what is tested."""


@pytest.fixture
def no_parts(monkeypatch):
    def run_realism(*args):
        raise Stop

    monkeypatch.setattr(avrisk.realism, "run_realism", run_realism)


def test_the_report_is_written_with_the_settings_and_progress_of_both_parts(
    tmp_path, short_parts
):
    seen = {"a": [], "b": []}
    out = tmp_path / "report"
    run = realism_report(
        out,
        seed=5,
        command="a test",
        progress_a=lambda *step: seen["a"].append(step),
        progress_b=lambda *step: seen["b"].append(step),
        **TINY,
    )
    assert sorted(p.name for p in run.files) == sorted(FILES.values())
    assert all(p.parent == out and p.is_file() for p in run.files)
    assert run.wall_s > 0
    settings = run.result.settings
    assert (settings.seed, settings.windows, settings.scenes) == (5, 3, 1)
    assert settings.held_out == "test"
    for part in ("a", "b"):
        model, done, total = seen[part][-1]
        assert done == total > 0
    figures = json.loads((out / "realism.json").read_text())
    assert figures["provenance"]["command"] == "a test"
    assert figures["provenance"]["drivers"]["shipped"] is True


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ({"brake_guard": "2"}, "a brake guard is GAP_FLOOR,ENGAGE_DECEL"),
        ({"held_out": "noon"}, "--held-out noon: not a held-out set"),
        ({"held_out": "0400pm-0415pm:train"}, "or a period's test split"),
        ({"drivers": "nowhere"}, "no such folder"),
    ],
)
def test_bad_input_is_a_user_error_before_any_work(tmp_path, no_parts, args, needle):
    if "drivers" in args:
        args = {"drivers": tmp_path / "nowhere"}
    with pytest.raises(UserError, match=needle):
        realism_report(tmp_path / "out", **args)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("name", "what"),
    [("driver_net.npz", "not a driver network"), ("xi_prior.npz", "not an xi prior")],
)
def test_a_damaged_or_missing_driver_file_is_a_user_error(
    tmp_path, no_parts, drivers_copy, name, what
):
    (drivers_copy / name).write_bytes(b"this is not a numpy archive")
    with pytest.raises(UserError, match=what):
        realism_report(tmp_path / "out", drivers=drivers_copy)
    (drivers_copy / name).unlink()
    with pytest.raises(UserError, match=f"lacks {name}"):
        realism_report(tmp_path / "out", drivers=drivers_copy)


def _trained_on(folder, periods):
    report = {"config": {"periods": periods}}
    (folder / "training_report.json").write_text(json.dumps(report))


def test_drivers_trained_on_the_held_out_period_are_warned_of(
    tmp_path, no_parts, drivers_copy, recwarn
):
    period = "0400pm-0415pm"
    _trained_on(drivers_copy, [period])
    with pytest.warns(NotHeldOutWarning, match=f"trained on {period}"):
        with pytest.raises(Stop):
            realism_report(tmp_path / "out", drivers=drivers_copy, held_out=period)
    recwarn.clear()
    _trained_on(drivers_copy, ["0500pm-0515pm"])
    with pytest.raises(Stop):
        realism_report(tmp_path / "out", drivers=drivers_copy, held_out=period)
    assert not [w for w in recwarn if w.category is NotHeldOutWarning]
    _trained_on(drivers_copy, [period])  # its test split is held out
    with pytest.raises(Stop):
        realism_report(
            tmp_path / "out", drivers=drivers_copy, held_out=f"{period}:test"
        )
    assert not [w for w in recwarn if w.category is NotHeldOutWarning]
