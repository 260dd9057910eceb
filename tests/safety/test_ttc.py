import math

import pytest
import torch

from avrisk.safety import MinTTC, get_safety_measure
from avrisk.sim.state import VehicleState

CAR = (4.0, 2.0)  # length, width [m]


def car(x, y=0.0, heading=0.0, speed=0.0, size=CAR):
    return [x, y, heading, speed, *size]


def ttc(*rows, shape=(1,), n_rays=360, max_range=100.0, dtype=torch.float32):
    state = VehicleState.from_rows([list(r) for r in rows], dtype=dtype)
    if shape != (1,):
        state = state.map(lambda t: t[0].expand(*shape, -1).contiguous())
    return MinTTC(n_rays, max_range, dtype=dtype).instant(state)


@pytest.mark.parametrize("shape", [(), (1,), (7,)])
def test_rear_end_approach_gives_gap_over_closing_speed(shape):
    t = ttc(car(0, speed=20), car(22, speed=10), shape=shape)
    assert t.shape == shape
    # From the ego centre to the lead's rear: 22 - 2 = 20 m at 10 m/s.
    assert torch.all(t == 2.0)


def test_head_on_approach_gives_gap_over_the_sum_of_speeds():
    t = ttc(car(0, speed=20), car(30, heading=math.pi, speed=10))
    assert t.item() == pytest.approx(28.0 / 30.0, rel=1e-6)


def test_a_vehicle_approaching_from_behind_counts():
    t = ttc(car(0, speed=10), car(-25, speed=15))
    assert t.item() == pytest.approx(23.0 / 5.0, rel=1e-6)


def test_a_receding_vehicle_gives_infinite_ttc():
    assert ttc(car(0, speed=10), car(20, speed=15)).item() == math.inf


def test_an_equal_speed_vehicle_gives_infinite_ttc():
    assert ttc(car(0, speed=10), car(20, speed=10)).item() == math.inf


def test_a_lone_ego_has_infinite_ttc():
    assert ttc(car(0, speed=10)).item() == math.inf


def test_a_vehicle_cutting_in_from_the_side_is_timed_along_the_perpendicular_ray():
    # Turned across the road, 5 m left, moving right at 5 m/s: its near side
    # (half its length, 2 m) is 3 m away on the 90-degree ray, the only ray
    # with the full closing speed; slanted rays see 3 / (5 sin^2).
    t = ttc(car(0, speed=0), car(0, y=5.0, heading=-math.pi / 2, speed=5.0))
    assert t.item() == pytest.approx(0.6, rel=1e-5)


def test_only_the_first_vehicle_on_a_ray_counts():
    fast_behind = car(30, speed=0)  # would give 28 / 20 = 1.4 s on its own
    assert ttc(car(0, speed=20), fast_behind).item() == pytest.approx(1.4, rel=1e-6)
    receding_in_front = car(15, speed=25)  # hides it completely
    assert ttc(car(0, speed=20), receding_in_front, fast_behind).item() == math.inf


def test_vehicles_beyond_the_ray_range_are_ignored():
    assert ttc(car(0, speed=20), car(120, speed=0), max_range=100.0).item() == math.inf
    assert ttc(
        car(0, speed=20), car(90, speed=0), max_range=100.0
    ).item() == pytest.approx(4.4)


def test_ttc_stays_positive_when_the_rectangles_already_overlap():
    # Boxes overlap (3.9 < 4) but the ego centre is 1.9 m from the other's rear.
    t = ttc(car(0, speed=20), car(3.9, speed=10))
    assert t.item() == pytest.approx(0.19, rel=1e-5)


def test_ttc_is_zero_when_the_ego_centre_is_inside_an_approaching_vehicle():
    # Zero up to the smallest normal float that stands in for the 0 distance.
    assert 0.0 <= ttc(car(0, speed=20), car(1.0, speed=10)).item() < 1e-37


def test_ttc_in_float64_matches_float32():
    rows = (car(0, speed=20), car(30, y=1.0, heading=math.pi - 0.1, speed=10))
    t32 = ttc(*rows)
    t64 = ttc(*rows, dtype=torch.float64)
    assert t32.item() == pytest.approx(t64.item(), rel=1e-5)


def test_the_running_minimum_only_changes_for_live_rollouts():
    m = MinTTC()
    carry = m.init(torch.tensor([3.0, 3.0]))
    carry = m.update(carry, torch.tensor([1.0, 1.0]), torch.tensor([True, False]))
    assert m.finalize(carry).tolist() == [1.0, 3.0]


def test_the_measure_is_found_by_name():
    assert isinstance(get_safety_measure("min_ttc", n_rays=8), MinTTC)
    with pytest.raises(KeyError, match="min_ttc"):
        get_safety_measure("nope")
