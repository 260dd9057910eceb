import math

import pytest
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.lane_change import (
    LANE_CHANGE_NOISE_STREAM,
    LaneChangeParams,
    LaneChangingDriver,
    target_lane_gaps,
)
from avrisk.agents.drivers.sampling import DRIVER_NOISE_STREAM
from avrisk.agents.drivers.store import load_driver_net
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.tensors.noise import normal

W = 3.7


@pytest.fixture(scope="module")
def net():
    """The shipped network: its trained lateral head carries out the changes."""
    return load_driver_net()


def sim(road, horizon):
    return Simulator(road, SimConfig(horizon=horizon), measure=MinTTC(n_rays=1))


def rows(*vehicles):
    """(x, lane, speed) per vehicle -> one rollout's state rows, cars 4.8 x 1.9."""
    return [[x, (lane + 0.5) * W, 0.0, v, 4.8, 1.9] for x, lane, v in vehicles]


def everyone(n):
    return torch.ones(n, dtype=torch.bool)


def test_the_layer_extends_the_drivers_noise_and_leaves_its_slice_unchanged(net):
    seeds = torch.tensor([3, 99])
    alone = normal(seeds, 7, DRIVER_NOISE_STREAM, (4, 2))
    extended = normal(seeds, 7, DRIVER_NOISE_STREAM, (3, 4, 2))
    assert torch.equal(extended[:, 0], alone)
    road = Road(n_lanes=3)
    sampled = LaneChangingDriver(LearnedDriver(net, controlled=everyone(4)), road)
    assert sampled.noise.stream == DRIVER_NOISE_STREAM
    assert sampled.noise.shape == (3, 4, 2)
    mean = LearnedDriver(net, controlled=everyone(4), stochastic=False)
    assert LaneChangingDriver(mean, road).noise.stream == LANE_CHANGE_NOISE_STREAM


@pytest.mark.parametrize("stochastic", [False, True])
def test_without_desires_a_rollout_is_the_bare_networks_bit_for_bit(net, stochastic):
    road = Road(n_lanes=3)
    state = VehicleState.from_rows(
        [rows((0.0, 1, 20.0), (30.0, 1, 15.0), (10.0, 0, 18.0))] * 2
    )
    bare = LearnedDriver(net, controlled=everyone(3), stochastic=stochastic)
    layered = LaneChangingDriver(bare, road, LaneChangeParams(rate=0.0))
    seeds = torch.tensor([5, 6])
    a = sim(road, 3.0).run(state, [bare], seeds, record_trace=True).trace
    b = sim(road, 3.0).run(state, [layered], seeds, record_trace=True).trace
    assert torch.equal(a.x, b.x) and torch.equal(a.y, b.y)


def test_gaps_and_closing_speeds_to_the_nearest_vehicles_of_a_lane(net):
    road = Road(n_lanes=4)
    sim_ = sim(road, 0.1)
    state = VehicleState.from_rows(
        [
            rows((0.0, 1, 20.0), (20.0, 2, 15.0), (-30.0, 2, 25.0), (8.0, 3, 0.0))
            + [[60.0, 3.0 * W, 0.0, 10.0, 4.8, 1.9]]  # on the 2|3 marking
        ]
    )
    obs = sim_.observe(state, torch.tensor([0]))
    query = torch.full((1, 5, 1), 2)
    lead_gap, lead_close, back_gap, back_close = target_lane_gaps(obs, query, W)
    # Vehicle 0 in lane 2: vehicle 1 ahead (20 - 4.8 m, closing at 5 m/s),
    # vehicle 2 behind (30 - 4.8 m, closing at 5 m/s); vehicle 3 is a lane over.
    assert lead_gap[0, 0, 0].item() == pytest.approx(15.2)
    assert lead_close[0, 0, 0].item() == pytest.approx(5.0)
    assert back_gap[0, 0, 0].item() == pytest.approx(25.2)
    assert back_close[0, 0, 0].item() == pytest.approx(5.0)
    # The vehicle on the marking occupies lane 2: it leads vehicle 1 there.
    assert lead_gap[0, 1, 0].item() == pytest.approx(35.2)
    # Nobody ahead of the marking-straddler in lane 2.
    assert lead_gap[0, 4, 0].item() == math.inf


@pytest.mark.parametrize(
    ("other", "changes"),
    [
        ((2.0, 1, 20.0), False),  # alongside: no gap
        ((-15.0, 1, 30.0), False),  # closing from behind: TTC 1 s
        ((60.0, 1, 20.0), True),  # far ahead: room
    ],
)
def test_gap_acceptance_refuses_a_change_into_a_too_small_gap(net, other, changes):
    road = Road(n_lanes=2)
    state = VehicleState.from_rows([rows((0.0, 0, 20.0), other)])
    eager = LaneChangeParams(rate=100.0, min_gap=4.0, min_ttc=4.0)
    changer = LaneChangingDriver(
        LearnedDriver(net, controlled=torch.tensor([True, False]), stochastic=False),
        road,
        eager,
    )
    keeper = LearnedDriver(
        net, controlled=torch.tensor([False, True]), stochastic=False
    )
    trace = (
        sim(road, 2.0)
        .run(state, [keeper, changer], torch.tensor([1]), record_trace=True)
        .trace
    )
    moved = trace.y[0, :, 0].max().item() - 0.5 * W
    assert (moved > 0.5) == changes, moved


def test_the_hazard_rate_is_reproduced_in_a_simulator_run(net):
    # Three vehicles per rollout, 300 m apart on a 5-lane road: nothing ever
    # refuses a change, so every desire starts one at once. Desires arrive in
    # a step with probability 1 - exp(-rate dt) while a vehicle keeps its lane.
    road, rate, b, n_steps = Road(n_lanes=5), 0.1, 32, 300
    state = VehicleState.from_rows(
        [rows((0.0, 2, 20.0), (300.0, 1, 20.0), (600.0, 3, 20.0))] * b
    )
    driver = LaneChangingDriver(
        LearnedDriver(net, controlled=everyone(3), stochastic=False),
        road,
        LaneChangeParams(rate=rate),
    )
    s = sim(road, n_steps * 0.1)
    seeds = torch.arange(b, dtype=torch.int64)
    masks = s.controlled([driver], 3)
    with torch.no_grad():
        carry, _ = s.start(s.prepare(state), [driver], seeds, [None])
        eligible = started = 0
        for t in range(n_steps):
            before = carry.actors[0].changing
            carry, _ = s.step(carry, t, seeds, [driver], masks)
            after = carry.actors[0].changing
            eligible += int((~before).sum())
            started += int((~before & after).sum())
    expected = eligible * -math.expm1(-rate * 0.1)
    assert expected > 50
    # Poisson: 4 standard deviations (two-sided false-failure rate 6e-5).
    assert abs(started - expected) < 4 * math.sqrt(expected), (started, expected)


def test_rollouts_with_lane_changes_are_reproducible_and_batch_independent(net):
    road = Road(n_lanes=4)
    g = torch.Generator().manual_seed(0)
    b = 6
    scenes = [
        rows(
            (0.0, int(torch.randint(0, 4, (1,), generator=g)), 20.0),
            (25.0, 1, 18.0),
            (-20.0, 2, 22.0),
        )
        for _ in range(b)
    ]
    state = VehicleState.from_rows(scenes)
    driver = LaneChangingDriver(
        LearnedDriver(net, controlled=everyone(3)), road, LaneChangeParams(rate=0.5)
    )
    seeds = torch.arange(40, 40 + b)
    batch = sim(road, 4.0).run(state, [driver], seeds, record_trace=True).trace
    again = sim(road, 4.0).run(state, [driver], seeds, record_trace=True).trace
    assert torch.equal(batch.y, again.y)
    lanes = road.lane_index(batch.y)
    assert bool((lanes != lanes[:, :1]).any()), "no lane change: the test is void"
    order = torch.tensor([4, 1, 5, 0, 3, 2])
    permuted = sim(road, 4.0).run(
        state[order], [driver], seeds[order], record_trace=True
    )
    assert torch.equal(permuted.trace.y, batch.y[order])
    alone = sim(road, 4.0).run(state[2:3], [driver], seeds[2:3], record_trace=True)
    assert torch.equal(alone.trace.y[0], batch.y[2])
    other_seeds = sim(road, 4.0).run(state, [driver], seeds + 1, record_trace=True)
    assert not torch.equal(other_seeds.trace.y, batch.y)


def test_settings_are_checked():
    with pytest.raises(ValueError, match="rate must be finite and >= 0"):
        LaneChangeParams(rate=-1.0)
    with pytest.raises(ValueError, match="offset_clip must be > 0"):
        LaneChangeParams(offset_clip=0.0)
