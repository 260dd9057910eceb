"""A failure card: parameters with units, absolute positions, two percentiles."""

import pytest

from avrisk.assembly import scenario_typicality
from avrisk.report.failures import failure_view, vehicle_starts
from avrisk.scenario import load_spec


@pytest.fixture(scope="module")
def spec():
    return load_spec("highway_idm")


def _row(spec, **extra):
    row = {}
    for j in range(spec.n_vehicles):
        row |= {f"veh{j}.s": 100.0 + j, f"veh{j}.t": 0.1 * j}
        row |= {f"veh{j}.heading": 1.5, f"veh{j}.speed": 12.0}
    row |= {"f": 0.0, "log_p0": -40.0, "phase": "final", "stage": 0}
    return row | {"sample_id": 7, "crash": True} | extra


def test_vehicles_start_at_absolute_positions(spec):
    starts = vehicle_starts(_row(spec), spec)
    assert [v["name"] for v in starts[:2]] == ["ego", "vehicle 1"]
    assert starts[0]["driver"] == "idm_mobil" and starts[1]["driver"] == "stop_and_go"
    for j, (v, slot) in enumerate(zip(starts, spec.vehicles, strict=True)):
        assert v["x"] == pytest.approx(slot.offset + 100.0 + j)  # not slot-relative
        lane_centre = (slot.lane + 0.5) * spec.road.lane_width
        assert v["y"] == pytest.approx(lane_centre + 0.1 * j)
        assert v["lane"] == slot.lane and v["speed"] == 12.0


def test_a_card_says_what_happened_with_units(spec):
    row = _row(spec, contact=1, collision_with=1, weird=2.5)
    card = failure_view(
        row,
        spec,
        scenario_typicality(spec),
        names=[*row],
        units={"weird": "m/s^2"},
        step="the final stage",
        animation=None,
    )
    assert card["what"] == "rear-end: the ego hits the vehicle ahead, vehicle 1 hit"
    assert 0.0 <= card["situation"] <= 100.0
    assert card["drivers"] is None  # highway_idm has no learned drivers
    assert card["step"] == "the final stage"
    assert len(card["vehicles"]) == spec.n_vehicles
    assert "veh" not in card["params"]  # the vehicles are in their own table
    assert "weird = 2.5 m/s^2" in card["params"]
    # without a scenario (a black box), parameters as recorded, with units
    plain = failure_view(
        row,
        None,
        None,
        names=["veh0.s"],
        units={"veh0.s": "m"},
        step="the final stage",
        animation=None,
    )
    assert plain["params"] == "veh0.s = 100 m" and plain["situation"] is None
