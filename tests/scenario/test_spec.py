"""Scenario spec: loading, validation and error messages."""

from pathlib import Path

import pytest
import yaml

from avrisk.scenario import (
    MAX_SPEC_BYTES,
    VEHICLE_FIELDS,
    ScenarioSpec,
    ScenarioSpecError,
    bundled_scenarios,
    load_spec,
    spec_from_dict,
)


def _minimal() -> dict:
    return {
        "name": "tiny",
        "vehicles": [
            {"lane": 1, "offset": 0.0},
            {"lane": 1, "offset": 60.0},
            {"lane": 2, "offset": 0.0},
        ],
    }


def _error(data: dict) -> str:
    with pytest.raises(ScenarioSpecError) as info:
        spec_from_dict(data, source="test.yaml")
    return str(info.value)


def test_the_default_scenario_is_learned_traffic_on_the_idm_scenarios_road():
    idm, learned = load_spec("highway_idm"), load_spec("highway_default")
    assert {"highway_idm", "highway_default"} <= set(bundled_scenarios())
    assert learned.road == idm.road and learned.simulation == idm.simulation
    for name in VEHICLE_FIELDS:  # the same marginals; a finite-variance CE box
        ours, theirs = (
            getattr(learned.initial_conditions, name),
            getattr(idm.initial_conditions, name),
        )
        assert ours.model_copy(update={"search": theirs.search}) == theirs
        assert ours.search == (1.0, 3.9) and ours.search[1] < 2 * min(ours.a, ours.b)
    roles = ("lane", "length", "width")
    assert [v.model_dump(include=set(roles)) for v in learned.vehicles] == [
        v.model_dump(include=set(roles)) for v in idm.vehicles
    ]
    assert learned.learned_slots == (False,) + (True,) * 5
    assert learned.ego.policy == "lidar_imitation"
    assert learned.learned_drivers.actions == "mean"
    assert learned.learned_drivers.xi_search == 0.0


def test_the_bundled_idm_scenario_loads_by_name_with_the_papers_marginals():
    spec = load_spec("highway_idm")
    assert "highway_idm" in bundled_scenarios()
    assert spec.road.n_lanes == 6 and spec.road.lane_width == 3.7
    assert spec.n_vehicles == 6
    ic = spec.initial_conditions
    assert (ic.s.lo, ic.s.scale, ic.s.a, ic.s.b) == (80.0, 40.0, 2.0, 2.0)
    assert (ic.t.lo, ic.t.scale) == (-0.25, 0.5)
    assert (ic.heading.lo, ic.heading.scale) == (-3.6, 7.2)
    assert (ic.speed.lo, ic.speed.scale) == (10.0, 10.0)
    assert ic.s.search == (1.0, 3.9)  # finite-variance weights (BENCHMARKS.md)


def test_a_spec_file_loads_from_a_path_and_round_trips_through_yaml(tmp_path: Path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(_minimal()))
    spec = load_spec(path)
    assert isinstance(spec, ScenarioSpec)
    again = tmp_path / "again.yaml"
    again.write_text(spec.to_yaml())
    assert load_spec(again) == spec


def test_defaults_fill_in_the_papers_values():
    spec = spec_from_dict(_minimal())
    assert spec.initial_conditions.speed.mean == pytest.approx(15.0)
    assert spec.safety.n_rays == 360 and spec.simulation.dt == 0.1
    assert spec.driver_for(1) == spec.drivers["default"]
    assert spec.driver_for(0) == spec.ego.params


def test_learned_drivers_take_no_idm_parameters_and_dump_without_them():
    data = _minimal() | {
        "drivers": {"calm": {"desired_speed": 20.0}, "human": {"model": "learned"}},
        "ego": {"policy": "lidar_imitation"},
    }
    data["vehicles"][1]["driver"] = "human"
    data["vehicles"][2]["driver"] = "calm"
    spec = spec_from_dict(data)
    assert spec.learned_slots == (False, True, False) and spec.has_learned_drivers
    assert not spec_from_dict(_minimal()).has_learned_drivers
    dumped = yaml.safe_load(spec.to_yaml())
    assert dumped["drivers"]["human"] == {"model": "learned"}
    assert dumped["ego"] == {"policy": "lidar_imitation"}
    assert dumped["drivers"]["calm"]["desired_speed"] == 20.0
    assert spec_from_dict(dumped) == spec

    data["drivers"]["human"]["desired_speed"] = 20.0
    message = _error(data)
    assert "drivers.human: model 'learned' takes no IDM+MOBIL parameters" in message
    assert "remove desired_speed" in message


def test_the_learned_drivers_section_defaults_to_the_paper_and_needs_learned_drivers():
    data = _minimal() | {"drivers": {"human": {"model": "learned"}}}
    spec = spec_from_dict(data)
    assert spec.learned_drivers.actions == "sampled"
    assert spec.learned_drivers.stochastic
    assert (spec.learned_drivers.xi_search, spec.learned_drivers.xi_search_unit) == (
        0.01,
        "absolute",
    )
    section = {"actions": "mean", "xi_search": 0.5, "xi_search_unit": "prior_sd"}
    tuned = spec_from_dict(data | {"learned_drivers": section})
    assert not tuned.learned_drivers.stochastic
    assert yaml.safe_load(tuned.to_yaml())["learned_drivers"] == section
    assert spec_from_dict(yaml.safe_load(tuned.to_yaml())) == tuned

    idm_only = _minimal() | {"learned_drivers": {"actions": "mean"}}
    assert "no vehicle has a 'model: learned' driver" in _error(idm_only)
    assert "learned_drivers" not in spec_from_dict(_minimal()).to_yaml()
    bad = data | {"learned_drivers": {"actions": "greedy", "xi_search": -1}}
    message = _error(bad)
    assert "learned_drivers.actions" in message
    assert "learned_drivers.xi_search" in message


def test_a_slot_override_replaces_only_the_named_marginal():
    data = _minimal()
    data["vehicles"][1]["initial"] = {"speed": {"lo": 5.0, "scale": 2.0}}
    spec = spec_from_dict(data)
    assert spec.initial_for(1).speed.lo == 5.0
    assert spec.initial_for(1).s == spec.initial_conditions.s
    assert spec.initial_for(2) == spec.initial_conditions


@pytest.mark.parametrize(
    ("patch", "expected"),
    [
        ({"road": {"n_lanes": 0}}, "road.n_lanes"),
        ({"road": {"lane_width": 9.0}}, "road.lane_width"),
        ({"road": {"lenght": 500}}, "did you mean 'length'"),
        ({"colour": "red"}, "colour: unknown field"),
        ({"simulation": {"dt": 0.0}}, "simulation.dt"),
        ({"simulation": {"dt": 0.1, "horizon": 1.05}}, "whole number"),
        ({"safety": {"n_rays": 2}}, "safety.n_rays"),
        ({"safety": {"measure": "min ttc"}}, "safety.measure"),
        ({"ego": {"params": {"desired_speed": -1}}}, "ego.params.desired_speed"),
        ({"drivers": {"default": {"politeness": 2}}}, "drivers.default.politeness"),
        ({"drivers": {"default": {"model": "GAIL"}}}, "drivers.default.model"),
        ({"ego": {"policy": "pilot-net"}}, "ego.policy"),
        (
            {"initial_conditions": {"speed": {"lo": 10, "scale": 0}}},
            "initial_conditions.speed.scale",
        ),
        (
            {"initial_conditions": {"s": {"lo": 80, "scale": 40, "a": 9}}},
            "search box",
        ),
        (
            {"initial_conditions": {"s": {"lo": 0, "scale": 1, "search": [7, 2]}}},
            "initial_conditions.s.search",
        ),
        (
            {"initial_conditions": {"heading": {"lo": -60, "scale": 120}}},
            "heading support",
        ),
        ({"name": "has space"}, "name"),
    ],
)
def test_each_kind_of_bad_field_gives_an_error_naming_it(patch, expected):
    data = _minimal() | patch
    message = _error(data)
    assert expected in message
    assert message.startswith("test.yaml: invalid scenario")


def test_vehicle_slot_errors_name_the_slot_and_the_fix():
    data = _minimal()
    data["vehicles"][2]["lane"] = 6
    assert "vehicles.2.lane: must be in [0, 5]" in _error(data)

    data = _minimal()
    data["vehicles"][0]["driver"] = "default"
    assert "vehicles.0.driver: slot 0 is the ego" in _error(data)

    data = _minimal()
    data["vehicles"][1]["driver"] = "racer"
    assert "unknown driver type 'racer'" in _error(data)

    data = _minimal() | {"drivers": {"calm": {}, "rude": {}}}
    assert "vehicles.1.driver: required" in _error(data)

    data = _minimal()
    data["vehicles"][1]["width"] = 0.1
    assert "vehicles.1.width" in _error(data)

    data = _minimal() | {"vehicles": []}
    assert "vehicles" in _error(data)


def test_slots_that_could_start_overlapping_in_one_lane_are_rejected():
    data = _minimal()
    data["vehicles"][1]["offset"] = 20.0
    message = _error(data)
    assert "vehicles.0, vehicles.1" in message and "change one 'offset'" in message


def test_an_unknown_scenario_name_lists_the_bundled_ones():
    with pytest.raises(ScenarioSpecError, match="highway_idm"):
        load_spec("no_such_scenario")


def test_a_file_over_the_size_limit_is_refused(tmp_path: Path):
    path = tmp_path / "huge.yaml"
    path.write_text("#" * (MAX_SPEC_BYTES + 1))
    with pytest.raises(ScenarioSpecError, match="limit"):
        load_spec(path)


def test_invalid_yaml_and_non_mapping_documents_are_refused(tmp_path: Path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("road: [unclosed\n")
    with pytest.raises(ScenarioSpecError, match="not valid YAML"):
        load_spec(bad)
    listy = tmp_path / "list.yaml"
    listy.write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioSpecError, match="mapping"):
        load_spec(listy)


def test_yaml_tags_that_build_python_objects_are_not_executed(tmp_path: Path):
    evil = tmp_path / "evil.yaml"
    evil.write_text("name: !!python/object/apply:os.system ['true']\nvehicles: []\n")
    with pytest.raises(ScenarioSpecError, match="not valid YAML"):
        load_spec(evil)


def test_the_spec_is_immutable():
    spec = spec_from_dict(_minimal())
    with pytest.raises(Exception, match="frozen"):
        spec.road.n_lanes = 3
