"""Scenario files that YAML accepts but a scenario must not: one clear error each.

Duplicate keys (YAML keeps the last, silently), booleans where numbers go
(Pydantic reads ``true`` as 1), nesting or aliases that would exhaust Python,
huge values echoed back, and rollouts of millions of steps.
"""

import warnings
from importlib import resources
from pathlib import Path

import pytest

from avrisk.scenario import ScenarioSpecError, load_spec
from avrisk.scenario.errors import MAX_LINE
from avrisk.scenario.loading import MAX_DEPTH, MAX_NODES
from avrisk.scenario.spec import MAX_STEPS, WARN_STEPS

BUNDLED = (
    resources.files("avrisk.data.scenarios").joinpath("highway_idm.yaml").read_text()
)
MINIMAL = "name: tiny\nvehicles: [{lane: 0}]\n"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(text)
    return path


def _refused(tmp_path: Path, text: str) -> str:
    with pytest.raises(ScenarioSpecError) as info:
        load_spec(_write(tmp_path, text))
    return str(info.value)


def _edit(old: str, new: str) -> str:
    assert old in BUNDLED
    return BUNDLED.replace(old, new, 1)


# ---------------------------------------------------------------- duplicates
@pytest.mark.parametrize(
    ("text", "key", "line", "first"),
    [
        # a field twice in a section
        (_edit("  n_lanes: 6 ", "  n_lanes: 6\n  n_lanes: 5 "), "n_lanes", 33, 32),
        # a whole section twice
        (BUNDLED + "road: {n_lanes: 4}\n", "road", 116, 31),
        # twice on one line, in a flow mapping
        (MINIMAL + "road: {n_lanes: 2, n_lanes: 3}\n", "n_lanes", 3, 3),
        # inside a list item
        ("name: tiny\nvehicles:\n  - lane: 0\n    lane: 1\n", "lane", 4, 3),
        # a driver type defined twice
        (
            MINIMAL + "drivers:\n  a: {desired_speed: 20.0}\n  a: {}\n",
            "a",
            5,
            4,
        ),
    ],
    ids=["field", "section", "flow", "list-item", "driver-type"],
)
def test_a_duplicate_key_is_refused_naming_it_and_both_lines(
    tmp_path, text, key, line, first
):
    message = _refused(tmp_path, text)
    assert f"line {line}: duplicate key {key!r} (first given at line {first})" in (
        message
    )
    assert message.count("\n") == 0


def test_a_merge_key_may_be_overridden_without_a_duplicate_error(tmp_path):
    text = (
        "name: tiny\nvehicles: [{lane: 0}]\n"
        "x-base: &base {desired_speed: 20.0, max_accel: 1.0}\n"
    )
    # Unknown field x-base aside, the merge itself must not count as a duplicate.
    message = _refused(tmp_path, text + "drivers: {a: {<<: *base, max_accel: 2.0}}\n")
    assert "duplicate" not in message and "x-base" in message
    spec = load_spec(
        _write(
            tmp_path,
            MINIMAL
            + "drivers: {a: {<<: {desired_speed: 20.0}, desired_speed: 21.0}}\n",
        )
    )
    assert spec.drivers["a"].desired_speed == 21.0


# ------------------------------------------------------------------ booleans
@pytest.mark.parametrize(
    ("old", "new", "where"),
    [
        ("  n_lanes: 6 ", "  n_lanes: true ", "road.n_lanes"),  # int
        ("  lane_width: 3.7 ", "  lane_width: yes ", "road.lane_width"),  # float
        ("  curvature: 0.0 ", "  curvature: off ", "road.curvature"),  # 0 as false
        ("  dt: 0.1 ", "  dt: on ", "simulation.dt"),
        ("    desired_speed: 8.0", "    desired_speed: true", "drivers.stop_and_go"),
        (
            "    politeness: 0.1\n    lane_change_threshold: 5.0\n# Slot 0",
            "    politeness: false\n    lane_change_threshold: 5.0\n# Slot 0",
            "ego.params.politeness",
        ),
        (
            "{lo: 80.0,  scale: 40.0, a: 2.0, b: 2.0, search: [1.0, 3.9]}",
            "{lo: 80.0,  scale: 40.0, a: 2.0, b: 2.0, search: [true, 3.9]}",
            "initial_conditions.s.search",
        ),
        (
            "- {lane: 2, offset: 0.0,   length: 4.8,",
            "- {lane: 2, offset: no,   length: 4.8,",
            "vehicles.0.offset",
        ),
    ],
    ids=["int", "float", "false-as-zero", "dt", "driver", "ego", "tuple", "slot"],
)
def test_a_boolean_where_a_number_goes_is_refused(tmp_path, old, new, where):
    message = _refused(tmp_path, _edit(old, new))
    assert where in message and "must be a number, not a boolean" in message


def test_numbers_written_as_yaml_text_stay_accepted(tmp_path):
    # YAML 1.1 reads 1e-1 (no dot) as text; it has always been accepted.
    spec = load_spec(_write(tmp_path, _edit("  dt: 0.1 ", "  dt: 1e-1 ")))
    assert spec.simulation.dt == 0.1


# ------------------------------------------------------ nesting and aliases
@pytest.mark.parametrize(
    "text",
    [
        MINIMAL + "description: " + "[" * 5000 + "]" * 5000 + "\n",
        MINIMAL + "ego: {policy: constant, params: " + "{a: " * 3000 + "1" + "}" * 3000,
        MINIMAL + "x: " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1) + "\n",
        "- " * 2000 + "1\n",
    ],
    ids=["lists", "mappings", "just-over", "block-lists"],
)
def test_deep_nesting_is_refused_not_a_recursion_error(tmp_path, text):
    message = _refused(tmp_path, text)
    assert f"nested deeper than {MAX_DEPTH} levels" in message


def test_aliases_that_expand_hugely_are_refused(tmp_path):
    lines = ["a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for i in range(1, 7):
        refs = ", ".join([f"*a{i - 1}"] * 10)
        lines.append(f"a{i}: &a{i} [{refs}]")
    text = "\n".join(lines) + "\n" + MINIMAL + "ego: {policy: x, params: {x: *a6}}\n"
    message = _refused(tmp_path, text)
    assert f"expand to more than {MAX_NODES:,} values" in message


def test_aliases_chained_past_the_depth_limit_are_refused(tmp_path):
    lines = ["a0: &a0 [1]"]
    for i in range(1, MAX_DEPTH + 2):
        lines.append(f"a{i}: &a{i} [*a{i - 1}]")
    message = _refused(tmp_path, "\n".join(lines) + "\n")
    assert f"nesting deeper than {MAX_DEPTH} levels" in message


def test_small_anchors_and_aliases_stay_accepted(tmp_path):
    text = _edit(
        "  s:       {lo: 80.0,  scale: 40.0, a: 2.0, b: 2.0, search: [1.0, 3.9]}",
        "  s:       {lo: 80.0,  scale: 40.0, a: 2.0, b: 2.0, search: &box [1.0, 3.9]}",
    ).replace(
        "  t:       {lo: -0.25, scale: 0.5,  a: 2.0, b: 2.0, search: [1.0, 3.9]}",
        "  t:       {lo: -0.25, scale: 0.5,  a: 2.0, b: 2.0, search: *box}",
    )
    spec = load_spec(_write(tmp_path, text))
    assert spec.initial_conditions.t.search == (1.0, 3.9)


# ------------------------------------------------------------- huge values
@pytest.mark.parametrize(
    "text",
    [
        _edit("name: highway_idm", "name: " + "a" * 900_000),
        MINIMAL + "road: {n_lanes: " + "9" * 500_000 + "}\n",
        MINIMAL + "drivers:\n  ? '" + "b" * 500_000 + "'\n  : {bogus: 1}\n",
        MINIMAL + "ego: {policy: '" + "c" * 500_000 + "!'}\n",
        MINIMAL + "safety: {n_rays: '" + "d" * 500_000 + "'}\n",
    ],
    ids=["name", "number", "key", "component", "text-for-int"],
)
def test_a_huge_value_is_not_echoed_back_in_full(tmp_path, text):
    message = _refused(tmp_path, text)
    assert len(message) < 2_000
    assert all(len(line) <= MAX_LINE + 40 for line in message.splitlines())
    assert "more characters" in message or "an integer of 500,000 characters" in message


def test_a_description_has_a_length_limit(tmp_path):
    message = _refused(tmp_path, MINIMAL + "description: " + "x" * 20_000 + "\n")
    assert "description" in message and "10000" in message


# ------------------------------------------------------------ steps per rollout
@pytest.mark.parametrize(
    ("dt", "horizon"),
    [("0.0000001", "10.0"), ("0.001", "600.0"), ("1.0e-320", "10.0")],
)
def test_millions_of_steps_per_rollout_are_refused_stating_the_cost(
    tmp_path, dt, horizon
):
    text = _edit("  dt: 0.1 ", f"  dt: {dt} ").replace(
        "  horizon: 10.0 ", f"  horizon: {horizon} "
    )
    message = _refused(tmp_path, text)
    assert "time steps per rollout" in message
    assert f"more than the {MAX_STEPS:,} allowed" in message
    assert "times one of the bundled scenarios" in message


def test_many_steps_per_rollout_warn_with_the_cost(tmp_path):
    steps = 2 * WARN_STEPS
    text = _edit("  dt: 0.1 ", "  dt: 0.01 ").replace(
        "  horizon: 10.0 ", f"  horizon: {steps * 0.01:g} "
    )
    with pytest.warns(UserWarning, match=f"{steps:,} time steps per rollout"):
        spec = load_spec(_write(tmp_path, text))
    assert spec.simulation.n_steps == steps
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_spec("highway_idm")  # 100 steps: no warning
