import math

import pytest
import torch

from avrisk.sim.dynamics import BicycleLimits, bicycle_step
from avrisk.sim.state import VehicleState

F64 = torch.float64


def one_vehicle(x=0.0, y=0.0, heading=0.0, speed=10.0, length=5.0, width=2.0, batch=1):
    row = [x, y, heading, speed, length, width]
    return VehicleState.from_rows([[row]] * batch, dtype=F64)


DEFAULT_LIMITS = BicycleLimits()


def run(state, accel, steer, n, dt=0.1, limits=DEFAULT_LIMITS):
    a = torch.full(state.shape, accel, dtype=F64)
    d = torch.full(state.shape, steer, dtype=F64)
    for _ in range(n):
        state = bicycle_step(state, a, d, dt, limits)
    return state


def test_straight_constant_acceleration_follows_x_equals_v_t_plus_half_a_t_squared():
    s = run(one_vehicle(speed=10.0), accel=2.0, steer=0.0, n=30)  # 3 s
    assert s.x.item() == pytest.approx(10.0 * 3 + 0.5 * 2.0 * 9, rel=1e-12)
    assert s.speed.item() == pytest.approx(16.0, rel=1e-12)
    assert s.y.item() == 0.0 and s.heading.item() == 0.0


def test_driving_along_a_heading_moves_along_it():
    h = 0.3
    s = run(one_vehicle(heading=h, speed=10.0), accel=0.0, steer=0.0, n=10)
    assert s.x.item() == pytest.approx(10.0 * math.cos(h), rel=1e-7)
    assert s.y.item() == pytest.approx(10.0 * math.sin(h), rel=1e-7)


def test_constant_steering_drives_a_circle_of_the_bicycle_radius():
    length, steer, v = 5.0, 0.2, 10.0
    l_r = 0.5 * 0.6 * length
    beta = math.atan(0.5 * math.tan(steer))
    radius = l_r / math.sin(beta)
    yaw_rate = v * math.sin(beta) / l_r
    # Centre of the circle: left of the velocity direction (heading + beta).
    cx, cy = -radius * math.sin(beta), radius * math.cos(beta)
    s = one_vehicle(speed=v, length=length)
    for k in range(1, 41):
        s = run(s, accel=0.0, steer=steer, n=1)
        r = math.hypot(s.x.item() - cx, s.y.item() - cy)
        assert r == pytest.approx(radius, rel=1e-6)
        assert s.heading.item() == pytest.approx(yaw_rate * 0.1 * k, rel=1e-6)


def test_commands_beyond_the_physical_limits_are_clipped():
    limits = BicycleLimits(accel_max=3.0, max_steer=0.1, max_speed=12.0)
    fast = run(one_vehicle(speed=10.0), accel=50.0, steer=0.0, n=1, limits=limits)
    assert fast.speed.item() == pytest.approx(10.3)
    capped = run(one_vehicle(speed=10.0), accel=3.0, steer=0.0, n=20, limits=limits)
    assert capped.speed.item() == pytest.approx(12.0)
    hard = run(one_vehicle(speed=10.0), accel=0.0, steer=1.0, n=5, limits=limits)
    soft = run(one_vehicle(speed=10.0), accel=0.0, steer=0.1, n=5, limits=limits)
    assert hard.heading.item() == soft.heading.item()


def test_braking_past_standstill_reverses_down_to_the_reverse_limit():
    s = run(one_vehicle(speed=1.0), accel=-5.0, steer=0.0, n=20)
    assert s.speed.item() == pytest.approx(-9.0)
    s = run(one_vehicle(speed=1.0), accel=-9.0, steer=0.0, n=40)
    assert s.speed.item() == pytest.approx(BicycleLimits().min_speed)


@pytest.mark.parametrize("batch", [1, 7])
def test_each_vehicle_moves_independently_of_the_batch(batch):
    g = torch.Generator().manual_seed(3)
    rows = torch.rand(batch, 4, 6, generator=g, dtype=F64) * 10 + 1
    s = VehicleState.from_rows(rows.tolist(), dtype=torch.float32)
    a = torch.rand(batch, 4, generator=g) * 4 - 2
    d = torch.rand(batch, 4, generator=g) - 0.5
    out = bicycle_step(s, a, d, 0.1)
    for b in range(batch):
        alone = bicycle_step(
            s[b : b + 1, 2:3], a[b : b + 1, 2:3], d[b : b + 1, 2:3], 0.1
        )
        assert torch.equal(alone.x, out.x[b : b + 1, 2:3])
        assert torch.equal(alone.heading, out.heading[b : b + 1, 2:3])


def test_invalid_limits_are_rejected_with_the_value_named():
    with pytest.raises(ValueError, match="max_steer"):
        BicycleLimits(max_steer=2.0)
