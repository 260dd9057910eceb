"""``avrisk scenarios``: the bundled scenarios, listed and written out."""

import yaml
from typer.testing import CliRunner

from avrisk.cli.app import app
from avrisk.scenario import (
    bundled_folder,
    bundled_scenario_text,
    bundled_scenarios,
    load_spec,
)


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "80"})


def test_scenarios_lists_every_bundled_scenario_with_its_whole_description():
    result = invoke("scenarios")
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    rows = [  # a scenario's line starts at column 0; its description is indented
        ln for ln in lines if ln[:1].strip() and ln.split()[0] in bundled_scenarios()
    ]
    assert (
        [r.split()[0] for r in rows]
        == bundled_scenarios()
        == [
            "highway_default",
            "highway_idm",
            "highway_lane_changes",
            "highway_rare",
            "highway_sampled",
            "highway_vision",
        ]
    )
    assert all(len(line) <= 80 for line in lines) and "…" not in result.stdout
    idm = next(r for r in rows if r.split()[0] == "highway_idm")
    assert "6 vehicles, 10 s, ego idm_mobil" in idm
    text = " ".join(result.stdout.split())
    for name in bundled_scenarios():  # each description whole, wrapped
        assert " ".join(load_spec(name).description.split()) in text
    assert "avrisk/data/scenarios" in result.stderr  # where they live
    where = f"bundled in {bundled_folder()}"  # whole, to copy, however long
    assert all(len(ln) <= 80 or ln == where for ln in result.stderr.splitlines())


def test_show_prints_a_scenario_and_write_makes_a_starting_file(tmp_path):
    shown = invoke("scenarios", "show", "highway_idm")
    assert shown.exit_code == 0 and shown.stdout == bundled_scenario_text("highway_idm")
    target = tmp_path / "mine.yaml"
    result = invoke("scenarios", "show", "highway_idm", "--write", target)
    assert result.exit_code == 0, result.output
    assert target.read_text() == bundled_scenario_text("highway_idm")
    assert load_spec(target) == load_spec("highway_idm")  # a valid start
    assert f"avrisk run {target}" in " ".join(result.stderr.split())


def test_an_existing_file_is_kept_without_force(tmp_path):
    target = tmp_path / "mine.yaml"
    target.write_text("name: mine\n")
    refused = invoke("scenarios", "show", "highway_idm", "--write", target)
    assert refused.exit_code == 2 and "exists already" in refused.output
    assert "--force" in refused.output and target.read_text() == "name: mine\n"
    forced = invoke("scenarios", "show", "highway_idm", "--write", target, "--force")
    assert forced.exit_code == 0
    assert yaml.safe_load(target.read_text())["name"] == "highway_idm"


def test_an_unknown_name_lists_the_bundled_ones(tmp_path):
    result = invoke("scenarios", "show", "nope", "--write", tmp_path / "x.yaml")
    assert result.exit_code == 2
    assert "no bundled scenario 'nope'" in result.output
    assert "highway_default, highway_idm" in result.output
    assert not (tmp_path / "x.yaml").exists()
