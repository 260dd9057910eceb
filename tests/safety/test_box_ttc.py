import math

import numpy as np
import pytest
import torch

from avrisk.safety import MinBoxTTC, MinTTC, box_ttc, get_safety_measure
from avrisk.sim.geometry import boxes_overlap
from avrisk.sim.state import VehicleState

CAR = (4.0, 2.0)  # length, width [m]


def car(x, y=0.0, heading=0.0, speed=0.0, size=CAR):
    return [x, y, heading, speed, *size]


def state_of(*rows, dtype=torch.float64):
    return VehicleState.from_rows([list(r) for r in rows], dtype=dtype)


def ttc(*rows, dtype=torch.float64):
    state = state_of(*rows, dtype=dtype)
    return box_ttc(state, *state.cos_sin)


def test_rear_end_approach_gives_bumper_gap_over_closing_speed():
    # Centres 22 m apart, 2 m half-lengths each: 18 m bumper to bumper at 10 m/s.
    assert ttc(car(0, speed=20), car(22, speed=10)).item() == pytest.approx(1.8)


def test_head_on_approach_gives_gap_over_the_sum_of_speeds():
    t = ttc(car(0, speed=20), car(30, heading=math.pi, speed=10))
    assert t.item() == pytest.approx(26.0 / 30.0)


def test_a_vehicle_approaching_from_behind_counts():
    assert ttc(car(0, speed=10), car(-25, speed=15)).item() == pytest.approx(21 / 5)


@pytest.mark.parametrize("lead_speed", [10.0, 15.0])
def test_receding_or_equal_speed_vehicles_never_collide(lead_speed):
    assert ttc(car(0, speed=10), car(20, speed=lead_speed)).item() == math.inf


def test_a_parallel_pass_in_the_next_lane_is_not_a_near_collision():
    # Side by side, one lane (3.7 m) apart, passing at 15 m/s: the boxes can
    # never meet. The paper's ray TTC projects the passing speed on slanted
    # rays and reports about 2 * 2.7 m / 15 m/s = 0.36 s for the same scene.
    rows = (car(0, speed=20), car(0.5, y=3.7, speed=5))
    assert ttc(*rows).item() == math.inf
    ray = MinTTC(360, dtype=torch.float64).instant(state_of(*rows)).item()
    assert 0.3 < ray < 0.4


def test_overlapping_boxes_give_zero_and_touching_boxes_do_not():
    assert ttc(car(0, speed=10), car(3.9, speed=0)).item() == 0.0
    # Touching bumpers, closing: contact is now, so TTC is 0 in the limit but
    # the interiors do not overlap yet; moving apart: never.
    assert ttc(car(0, speed=10), car(4.0, speed=0)).item() == 0.0
    assert ttc(car(0, speed=0), car(4.0, speed=10)).item() == math.inf


def test_a_vehicle_crossing_ahead_is_timed_to_first_contact():
    # Ego stopped at the origin, pointing +x (nose at x = 2, left side at
    # y = 1); a car crossing from the left (heading -90 deg, 5 m/s, so its
    # 2 m width lies along x) with its centre 2.5 m ahead and 10 m to the left:
    # it spans x in [1.5, 3.5], and its front (y = 10 - 2) must cover 7 m.
    t = ttc(car(0), car(2.5, y=10.0, heading=-math.pi / 2, speed=5.0))
    assert t.item() == pytest.approx(7.0 / 5.0)
    # Centred 3 m ahead it spans [2, 4]: it grazes the nose, touching only.
    assert ttc(car(0), car(3.0, y=10.0, heading=-math.pi / 2, speed=5.0)).item() == (
        math.inf
    )


def test_the_minimum_runs_over_every_other_vehicle():
    t = ttc(car(0, speed=20), car(40, speed=10), car(14, speed=10), car(8, y=3.7))
    assert t.item() == pytest.approx(1.0)  # the car at 14 m: 10 m gap at 10 m/s


def test_a_lone_ego_has_infinite_ttc():
    assert ttc(car(0, speed=10)).item() == math.inf


def _first_overlap_on_a_grid(rows, horizon, dt):
    """Brute force: advance both boxes by dt and test overlap (SAT) each time."""
    s = state_of(*rows)
    c, sn = s.cos_sin
    taus = torch.arange(0.0, horizon, dt, dtype=torch.float64)
    x = s.x[0] + taus[:, None] * s.speed[0] * c[0]
    y = s.y[0] + taus[:, None] * s.speed[0] * sn[0]
    hit = boxes_overlap(
        x[:, 0], y[:, 0], c[0, 0], sn[0, 0], s.length[0, 0] / 2, s.width[0, 0] / 2,
        x[:, 1], y[:, 1], c[0, 1], sn[0, 1], s.length[0, 1] / 2, s.width[0, 1] / 2,
    )  # fmt: skip
    idx = torch.nonzero(hit).flatten()
    return taus[idx[0]].item() if len(idx) else math.inf


def test_agrees_with_stepping_the_boxes_forward_and_testing_overlap():
    # Random pairs of oriented boxes with random velocities: the analytic
    # first-contact time must match the first overlapping instant of a fine
    # time grid to within one grid step (and "never" must mean never).
    rng = np.random.default_rng(3)
    dt, horizon, checked = 1e-3, 6.0, 0
    for _ in range(150):
        ego_size = (rng.uniform(3, 6), rng.uniform(1.5, 2.6))
        other_size = (rng.uniform(3, 12), rng.uniform(1.5, 2.6))
        ego = car(0.0, rng.uniform(-1, 1), rng.uniform(-0.6, 0.6),
                  rng.uniform(0, 20), ego_size)  # fmt: skip
        other = car(rng.uniform(-30, 30), rng.uniform(-8, 8),
                    rng.uniform(-math.pi, math.pi), rng.uniform(0, 20),
                    other_size)  # fmt: skip
        rows = [ego, other]
        exact = ttc(*rows).item()
        brute = _first_overlap_on_a_grid(rows, horizon, dt)
        if exact >= horizon - dt:
            assert brute == math.inf
            continue
        checked += 1
        assert brute - dt <= exact <= brute + 1e-9, (rows, exact, brute)
    assert checked >= 20  # the sample really contains collisions


def test_batched_evaluation_matches_one_at_a_time():
    rng = np.random.default_rng(0)
    rows = rng.uniform([-30, -6, -1, 0, 3, 1.5], [30, 6, 1, 20, 12, 2.6], (8, 4, 6))
    batch = VehicleState.from_rows(rows.reshape(-1, 6).tolist(), dtype=torch.float64)
    batch = batch.map(lambda t: t.reshape(8, 4))
    together = box_ttc(batch, *batch.cos_sin)
    alone = torch.stack([ttc(*r) for r in rows.tolist()]).flatten()
    assert torch.equal(together, alone)


def test_registered_as_a_safety_measure_that_keeps_the_minimum_over_time():
    measure = get_safety_measure("min_box_ttc")
    assert isinstance(measure, MinBoxTTC)
    carry = measure.init(torch.tensor([2.0, 1.0]))
    carry = measure.update(carry, torch.tensor([0.5, 0.2]), torch.tensor([True, False]))
    assert measure.finalize(carry).tolist() == [0.5, 1.0]
