"""Registries: names, import paths, and params validated by each component."""

import pytest
from pydantic import BaseModel, Field

from avrisk.agents.policy import ConstantPolicy, EgoPolicy, get_policy
from avrisk.registry import (
    ComponentError,
    Registry,
    UnknownComponentError,
    check_component_name,
    is_import_path,
    load_component,
)
from avrisk.safety import get_safety_measure

USER_EGO = "tests.user_components:HoldSpeedEgo"


class _Gain(BaseModel):
    gain: float = Field(1.0, gt=0)


def _registry() -> Registry:
    reg = Registry("controller")
    reg.register("p_control", lambda gain, dt=0.1: (gain, dt), params=_Gain)
    reg.register("bang_bang", lambda: "bang")
    return reg


def test_params_are_validated_by_the_component_and_errors_name_the_field():
    ego = get_policy("constant", {"accel": "-2"}, n_vehicles=2)
    assert isinstance(ego, ConstantPolicy) and (ego.accel, ego.steer) == (-2.0, 0.0)
    with pytest.raises(ComponentError) as info:
        get_policy("constant", {"accel": "fast"})
    assert str(info.value) == (
        "ego policy 'constant': params.accel: Input should be a valid number, "
        "unable to parse string as a number (got 'fast')"
    )
    with pytest.raises(
        ComponentError,
        match=r"params.acel: unknown; did you mean .accel.\? allowed: accel",
    ):
        get_policy("constant", {"acel": 1.0})
    reg = _registry()
    assert reg.build("p_control", {"gain": 2}) == (2.0, 0.1)
    assert reg.build("p_control") == (1.0, 0.1)
    with pytest.raises(ComponentError, match=r"controller 'p_control': params.gain"):
        reg.build("p_control", {"gain": 0})


def test_a_component_without_a_params_model_takes_no_params():
    assert _registry().build("bang_bang", {}) == "bang"
    with pytest.raises(ComponentError) as info:
        get_policy("vision_pilotnet", {"desired_speed": 20.0})
    assert str(info.value) == (
        "ego policy 'vision_pilotnet' takes no params; remove desired_speed"
    )
    with pytest.raises(ComponentError, match="'min_ttc' takes no params"):
        get_safety_measure("min_ttc", {"n_rays": 8})


def test_the_callers_arguments_pass_through_and_may_not_be_given_as_params():
    reg = _registry()
    assert reg.build("p_control", {"gain": 3}, dt=0.5) == (3.0, 0.5)
    assert reg.build("p_control", gain=4.0) == (4.0, 0.1)  # code, not YAML
    with pytest.raises(ComponentError, match="params dt are set by avrisk"):
        reg.build("p_control", {"dt": 1.0}, dt=0.5)


def test_an_unknown_name_lists_the_known_ones():
    with pytest.raises(UnknownComponentError) as info:
        _registry().build("pid")
    assert isinstance(info.value, KeyError) and isinstance(info.value, ComponentError)
    assert str(info.value).startswith(
        "unknown controller 'pid'; known: bang_bang, p_control"
    )
    with pytest.raises(
        KeyError, match="constant, external, idm_mobil, lidar_imitation"
    ):
        get_policy("pilotnet")


def test_a_misspelt_name_is_given_the_closest_registered_one():
    with pytest.raises(UnknownComponentError) as info:
        get_policy("idm_mobill")
    assert str(info.value).startswith(
        "unknown ego policy 'idm_mobill' (did you mean 'idm_mobil'?); known: "
    )
    with pytest.raises(UnknownComponentError, match=r"^unknown ego policy 'zz'; k"):
        get_policy("zz")  # nothing close: no suggestion


def test_registered_names_are_lowercase_identifiers_and_unique():
    reg = _registry()
    with pytest.raises(ValueError, match="lowercase"):
        reg.register("PControl", lambda: None)
    with pytest.raises(ValueError, match="already registered"):
        reg.register("p_control", lambda: None)
    assert reg.names() == ["bang_bang", "p_control"]


def test_an_import_path_is_refused_unless_importing_is_allowed():
    with pytest.raises(ComponentError) as info:
        get_policy(USER_EGO, {"speed": 25.0})
    message = str(info.value)
    assert f"names ego policy {USER_EGO!r} by import path" in message
    assert "only from a scenario given on the command line" in message
    with pytest.raises(ComponentError, match="by import path"):
        load_component(USER_EGO, allow_import=False)


def test_an_import_path_loads_the_users_class_and_validates_its_params():
    ego = get_policy(USER_EGO, {"speed": 25}, allow_import=True)
    assert isinstance(ego, EgoPolicy) and (ego.speed, ego.gain) == (25.0, 0.5)
    assert type(ego) is load_component(USER_EGO, allow_import=True)
    with pytest.raises(ComponentError) as info:
        get_policy(USER_EGO, {"speed": -1}, allow_import=True)
    assert str(info.value) == (
        f"ego policy {USER_EGO!r}: params.speed: Input should be greater than "
        "or equal to 0 (got -1)"
    )
    with pytest.raises(ComponentError, match="must be a subclass of pydantic"):
        get_policy("tests.user_components:MisdeclaredEgo", allow_import=True)
    with pytest.raises(ComponentError, match="is 30.0, not a class or factory"):
        get_policy("tests.user_components:SPEED_LIMIT", allow_import=True)


def test_a_missing_module_or_attribute_is_named(tmp_path, monkeypatch):
    with pytest.raises(ComponentError, match="no module named 'no_such_pkg'"):
        load_component("no_such_pkg.egos:Ego", allow_import=True)
    with pytest.raises(ComponentError) as info:
        load_component("tests.user_components:HoldSpeed", allow_import=True)
    assert "has no attribute 'HoldSpeed'; did you mean 'HoldSpeedEgo'?" in str(
        info.value
    )
    (tmp_path / "needs_missing_dep.py").write_text("import no_such_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ComponentError, match="importing failed: No module named"):
        load_component("needs_missing_dep:Ego", allow_import=True)


@pytest.mark.parametrize(
    "name", ["idm_mobil", "_private", "mypkg.egos:MyEgo", "egos:My_Ego2"]
)
def test_well_formed_names(name):
    assert check_component_name(name) == name
    assert is_import_path(name) == (":" in name)


@pytest.mark.parametrize(
    ("name", "hint"),
    [
        ("Pilot Net", "is neither a registered name"),
        ("min-ttc", "is neither a registered name"),
        ("mypkg.egos.MyEgo", "did you mean 'mypkg.egos:MyEgo'?"),
        ("mypkg:egos:MyEgo", "import path 'package.module:attribute'"),
        ("mypkg.:MyEgo", "import path 'package.module:attribute'"),
        ("", "is neither"),
    ],
)
def test_malformed_names_are_explained(name, hint):
    with pytest.raises(ComponentError, match=hint):
        check_component_name(name)
