"""The bundled scenarios through the API: listed, shown, written out."""

import pytest

from avrisk.api.scenarios import bundled, scenario_yaml
from avrisk.scenario import ScenarioSpecError, load_spec


def test_every_bundled_scenario_is_listed_with_its_spec_and_folder():
    scenarios = bundled()
    assert "highway_default" in scenarios.specs
    assert list(scenarios.specs) == sorted(scenarios.specs)
    assert (scenarios.folder / "highway_default.yaml").is_file()
    assert scenarios.specs["highway_idm"] == load_spec("highway_idm")


def test_a_scenario_written_out_loads_as_the_bundled_one(tmp_path):
    out = tmp_path / "mine.yaml"
    text = scenario_yaml("highway_idm", out)
    assert out.read_text() == text == scenario_yaml("highway_idm")
    assert load_spec(out) == load_spec("highway_idm")
    with pytest.raises(ScenarioSpecError):
        scenario_yaml("no_such_scenario")
