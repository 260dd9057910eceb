import pytest
import torch

from avrisk.agents.drivers.guard import BrakeGuard

GUARD = BrakeGuard(gap_floor=2.0, engage_decel=1.0)
LENGTH = 4.8


def limit(accel, rng, rate, hit=0, guard=GUARD):
    t = torch.tensor
    return guard.limit(
        t([[accel]]), t([[rng]]), t([[rate]]), t([[hit]]), t([[LENGTH]])
    ).item()


def test_closing_fast_on_a_vehicle_ahead_brakes_to_stop_the_closing_at_the_floor():
    # bumper gap 12.4 - 2.4 = 10 m, 8 m left above the floor, closing at 8 m/s:
    # 64 / (2 * 8) = 4 m/s^2 needed
    assert limit(0.5, 12.4, -8.0) == pytest.approx(-4.0)


def test_the_networks_harder_braking_is_kept():
    assert limit(-5.0, 12.4, -8.0) == -5.0


def test_below_the_engaging_deceleration_the_network_drives_unchanged():
    # closing at 3 m/s with 8 m of room needs 0.5625 m/s^2 < 1
    assert limit(0.3, 12.4, -3.0) == pytest.approx(0.3)
    assert limit(0.3, 12.4, +3.0) == pytest.approx(0.3)  # opening


def test_a_beam_that_hits_no_vehicle_never_brakes():
    assert limit(0.3, 3.0, -20.0, hit=-1) == pytest.approx(0.3)


def test_inside_the_floor_the_room_is_floored_not_negative():
    # gap 1 m < floor: room 0.1 m, closing 1 m/s: 5 m/s^2
    assert limit(0.0, 1.0 + LENGTH / 2, -1.0) == pytest.approx(-5.0)


def test_a_slow_creep_inside_the_floor_is_braked_only_with_hold_floor():
    # gap 1.5 m < floor 2 m, closing at 0.4 m/s: 0.16 / 0.2 = 0.8 m/s^2 < 1
    creep = (0.2, 1.5 + LENGTH / 2, -0.4)
    assert limit(*creep) == pytest.approx(0.2)
    held = BrakeGuard(2.0, 1.0, hold_floor=True)
    assert limit(*creep, guard=held) == pytest.approx(-0.8)
    # outside the floor, or opening, or nothing hit: as without it
    assert limit(0.2, 2.5 + LENGTH / 2, -0.4, guard=held) == pytest.approx(0.2)
    assert limit(0.2, 1.5 + LENGTH / 2, +0.4, guard=held) == pytest.approx(0.2)
    assert limit(0.2, 1.5 + LENGTH / 2, -0.4, hit=-1, guard=held) == pytest.approx(0.2)


@pytest.mark.parametrize(
    ("text", "guard"),
    [
        ("2,1", BrakeGuard(2.0, 1.0)),
        ("0,0.5", BrakeGuard(0, 0.5)),
        ("2,2,hold", BrakeGuard(2.0, 2.0, hold_floor=True)),
        (" 2, 2, HOLD", BrakeGuard(2.0, 2.0, hold_floor=True)),
    ],
)
def test_a_guard_parses_from_gap_and_deceleration(text, guard):
    assert BrakeGuard.parse(text) == guard


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("2", "GAP_FLOOR,ENGAGE_DECEL"),
        ("x,1", "GAP_FLOOR"),
        ("-1,1", "gap_floor"),
        ("2,1,2", "hold"),
        ("2,1,hold,hold", "hold"),
    ],
)
def test_bad_guards_are_refused(text, match):
    with pytest.raises(ValueError, match=match):
        BrakeGuard.parse(text)
    with pytest.raises(ValueError, match="engage_decel"):
        BrakeGuard(1.0, 0.0)


def test_a_guard_round_trips_through_its_json_mapping():
    assert BrakeGuard.from_dict(GUARD.to_dict()) == GUARD
    assert BrakeGuard.from_dict({"gap_floor": 3, "engage_decel": 1}) == BrakeGuard(3, 1)
    held = BrakeGuard(2.0, 2.0, hold_floor=True)
    assert BrakeGuard.from_dict(held.to_dict()) == held
    assert BrakeGuard.parse(held.text()) == held
    assert BrakeGuard.parse(GUARD.text()) == GUARD


def test_a_guard_without_hold_floor_writes_the_metadata_of_before():
    # files written before hold_floor existed keep their bytes and meaning
    assert GUARD.to_dict() == {"gap_floor": 2.0, "engage_decel": 1.0}


@pytest.mark.parametrize(
    "data",
    [
        None,
        {},
        {"gap_floor": 1.0, "engage_decel": 1.0, "x": 0},
        {"gap_floor": True, "engage_decel": 1.0},
        {"gap_floor": 1.0, "engage_decel": 1.0, "hold_floor": 1},
        {"engage_decel": 1.0, "hold_floor": True},
    ],
)
def test_a_malformed_mapping_is_refused(data):
    with pytest.raises(ValueError, match="brake guard"):
        BrakeGuard.from_dict(data)


@pytest.mark.parametrize("text", ["inf,1", "1,inf", "nan,1"])
def test_settings_must_be_finite(text):
    with pytest.raises(ValueError, match="finite"):
        BrakeGuard.parse(text)
