"""Components chosen by name or import path, with params checked by the component."""

import datetime
import json
from pathlib import Path

import pytest
import yaml

from avrisk.agents.policy import get_policy
from avrisk.registry import ComponentError
from avrisk.scenario import ScenarioSpecError, load_spec, spec_from_dict
from avrisk.scenario.components import IDMSpec

USER_EGO = "tests.user_components:HoldSpeedEgo"


def _minimal(**sections) -> dict:
    return {
        "name": "tiny",
        "vehicles": [{"lane": 1, "offset": 0.0}, {"lane": 1, "offset": 60.0}],
    } | sections


def _two_driver_types(**sections) -> dict:
    """Slot 1 of type 'calm', slot 2 of type 'human'."""
    data = _minimal(**sections)
    data["vehicles"] = [
        {"lane": 1, "offset": 0.0},
        {"lane": 1, "offset": 60.0, "driver": "calm"},
        {"lane": 2, "offset": 0.0, "driver": "human"},
    ]
    return data


def _error(data: dict) -> str:
    with pytest.raises(ScenarioSpecError) as info:
        spec_from_dict(data, source="test.yaml")
    return str(info.value)


def test_a_spec_file_naming_a_users_ego_by_import_path_parses(tmp_path: Path):
    path = tmp_path / "user.yaml"
    path.write_text(
        "name: user_ego\n"
        f"ego: {{policy: '{USER_EGO}', params: {{speed: 25.0, gain: 0.8}}}}\n"
        "vehicles: [{lane: 1}, {lane: 1, offset: 60.0}]\n"
    )
    spec = load_spec(path)
    assert spec.ego.policy == USER_EGO
    assert spec.ego.params == {"speed": 25.0, "gain": 0.8}
    assert spec.driver_for(0) == IDMSpec()  # neighbours' model of a non-IDM ego
    assert spec.import_paths() == [USER_EGO]
    assert spec_from_dict(yaml.safe_load(spec.to_yaml())) == spec
    ego = get_policy(spec.ego.policy, spec.ego.params, allow_import=True)
    assert (ego.speed, ego.gain) == (25.0, 0.8)


def test_the_spec_is_pure_data_and_imports_nothing_it_names():
    spec = spec_from_dict(
        _minimal(
            ego={"policy": "nowhere_pkg.egos:Ego"},
            drivers={"default": {"model": "nowhere_pkg.drivers:Calm"}},
            safety={"measure": "nowhere_pkg.measures:Gap", "params": {"m": 1}},
        )
    )
    assert spec.import_paths() == [
        "nowhere_pkg.egos:Ego",
        "nowhere_pkg.drivers:Calm",
        "nowhere_pkg.measures:Gap",
    ]
    assert spec_from_dict(_minimal()).import_paths() == []


def test_a_registered_component_checks_its_params_when_built_not_when_parsed():
    spec = spec_from_dict(_minimal(ego={"policy": "constant", "params": {"x": 1}}))
    with pytest.raises(ComponentError, match=r"'constant': params.x: unknown"):
        get_policy(spec.ego.policy, spec.ego.params)
    spec = spec_from_dict(_minimal(ego={"policy": "pilotnet"}))
    with pytest.raises(
        ComponentError,
        match=r"ego policy 'pilotnet' \(did you mean 'vision_pilotnet'\?\); known",
    ):
        get_policy(spec.ego.policy, spec.ego.params)


def test_old_forms_load_to_equal_specs_and_dump_as_before():
    old = spec_from_dict(
        _two_driver_types(
            drivers={"calm": {"desired_speed": 20.0}, "human": {"model": "learned"}},
            ego={"policy": "lidar_imitation"},
            safety={"measure": "min_ttc", "n_rays": 90},
        )
    )
    explicit = spec_from_dict(
        _two_driver_types(
            drivers={
                "calm": {"model": "idm_mobil", "desired_speed": 20.0},
                "human": {"model": "learned", "params": {}},
            },
            ego={"policy": "lidar_imitation", "params": {}},
            safety={"measure": "min_ttc", "params": {}, "n_rays": 90},
        )
    )
    assert old == explicit
    dump = old.model_dump(mode="json")
    assert dump["ego"] == {"policy": "lidar_imitation"}
    assert dump["safety"] == {"measure": "min_ttc", "n_rays": 90}
    assert dump["drivers"]["human"] == {"model": "learned"}
    assert "params" not in dump["drivers"]["calm"]
    idm_ego = spec_from_dict(_minimal()).model_dump(mode="json")["ego"]
    assert idm_ego == {"policy": "idm_mobil", "params": IDMSpec().model_dump()}


def test_the_bundled_scenarios_dump_as_before_any_params_existed():
    for name in ("highway_default", "highway_idm"):
        dump = json.loads(json.dumps(load_spec(name).model_dump(mode="json")))
        assert "params" not in dump["safety"]
        assert all("params" not in driver for driver in dump["drivers"].values())
    assert load_spec("highway_default").model_dump(mode="json")["ego"] == {
        "policy": "lidar_imitation"
    }


def test_an_idm_ego_validates_its_params_here_and_another_ego_does_not():
    spec = spec_from_dict(_minimal(ego={"params": {"desired_speed": 20.0}}))
    assert spec.ego.params == IDMSpec(desired_speed=20.0) == spec.driver_for(0)
    assert "did you mean 'desired_speed'" in _error(
        _minimal(ego={"params": {"desired_sped": 20.0}})
    )
    other = spec_from_dict(
        _minimal(ego={"policy": "constant", "params": {"desired_speed": "x"}})
    )
    assert other.ego.params == {"desired_speed": "x"}  # constant's own to refuse


@pytest.mark.parametrize(
    ("section", "expected"),
    [
        (
            {"ego": {"policy": "mypkg.egos.MyEgo"}},
            "ego.policy: 'mypkg.egos.MyEgo' is neither a registered name",
        ),
        ({"ego": {"policy": "mypkg.egos.MyEgo"}}, "did you mean 'mypkg.egos:MyEgo'?"),
        (
            {"safety": {"measure": "a:b:c"}},
            "safety.measure: 'a:b:c' is neither a registered name",
        ),
        ({"ego": {"policy": "constant", "params": [1, 2]}}, "ego.params: "),
        (
            {"ego": {"policy": "constant", "params": {"t": datetime.date(2026, 1, 1)}}},
            "ego.params.t: input was not a valid JSON value",
        ),
        ({"safety": {"params": "fast"}}, "safety.params: "),
    ],
)
def test_malformed_names_and_params_are_explained(section, expected):
    assert expected in _error(_minimal(**section))


def test_driver_parameters_go_where_the_model_takes_them():
    def drivers(default: dict) -> dict:
        return _minimal(drivers={"default": default})

    custom = spec_from_dict(
        drivers({"model": "mypkg.drivers:Calm", "params": {"gain": 2}})
    )
    assert custom.drivers["default"].params == {"gain": 2}
    assert custom.learned_slots == (False, False)
    assert custom.model_dump(mode="json")["drivers"]["default"] == {
        "model": "mypkg.drivers:Calm",
        "params": {"gain": 2},
    }
    assert "model 'mypkg.drivers:Calm' takes no IDM+MOBIL parameters" in _error(
        drivers({"model": "mypkg.drivers:Calm", "desired_speed": 20.0})
    )
    assert "takes its parameters beside 'model'" in _error(
        drivers({"params": {"desired_speed": 20.0}})
    )
    assert "model 'learned' takes no params" in _error(
        drivers({"model": "learned", "params": {"actions": "mean"}})
    )
