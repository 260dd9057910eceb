import math

import pytest
import torch

from avrisk.agents import ConstantPolicy, IDMDriver, IDMParams, IDMState, ego_only
from avrisk.agents.idm import LANE_CHANGE_DELAY, idm_acceleration
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState

F64 = torch.float64


def simulator(road, config=None):
    config = SimConfig() if config is None else config
    return Simulator(road, config, measure=MinTTC(dtype=F64), dtype=F64)


def t(x):
    return torch.tensor(float(x), dtype=F64)


def idm(v, gap, v_lead, v0=30.0, time_headway=1.5, s0=2.0, a=1.0, b=1.5):
    return idm_acceleration(
        t(v), t(gap), t(v_lead), t(v0), t(time_headway), t(s0), t(a), t(b)
    ).item()


def test_free_road_acceleration_is_a_times_one_minus_speed_ratio_to_the_fourth():
    assert idm(10.0, math.inf, 0.0, v0=20.0, a=1.0) == pytest.approx(1.0 * (1 - 0.5**4))
    assert idm(20.0, math.inf, 0.0, v0=20.0) == 0.0


def test_following_at_the_equilibrium_gap_keeps_speed():
    v, v0, s0, time_headway = 20.0, 30.0, 2.0, 1.5
    gap = (s0 + v * time_headway) / math.sqrt(1 - (v / v0) ** 4)
    assert idm(v, gap, v, v0=v0, s0=s0, time_headway=time_headway) == pytest.approx(
        0.0, abs=1e-12
    )
    assert idm(v, gap * 1.1, v, v0=v0) > 0 > idm(v, gap * 0.9, v, v0=v0)


def test_closing_in_adds_the_braking_term_of_the_desired_gap():
    v, v_lead, gap, a, b = 20.0, 10.0, 30.0, 1.0, 1.5
    s_star = 2.0 + v * 1.5 + v * (v - v_lead) / (2 * math.sqrt(a * b))
    expected = a * (1 - (v / 30.0) ** 4 - (s_star / gap) ** 2)
    assert idm(v, gap, v_lead, a=a, b=b) == pytest.approx(expected, rel=1e-12)


def test_an_overlapping_leader_commands_full_braking():
    assert idm(20.0, -1.0, 20.0) < -1e3


# --- MOBIL and lane keeping through the simulator's observation ----------------

ROAD = Road(n_lanes=2, lane_width=4.0)  # lane 0 centre y = 2, lane 1 centre y = 6
SIZE = [4.0, 2.0]


def drive(rows, road=ROAD, **params):
    """One decision of IDM+MOBIL for every vehicle in the scene."""
    sim = simulator(road)
    state = VehicleState.from_rows(rows, dtype=F64)
    p = IDMParams.full(state.shape, dtype=F64, **params)
    obs = sim.observe(state, torch.zeros(1, dtype=torch.int64))
    driver = IDMDriver(p, road)
    return driver.act(obs, driver.init(obs, None), None)


EGO = [0.0, 2.0, 0.0, 25.0, *SIZE]
SLOW_AHEAD = [25.0, 2.0, 0.0, 10.0, *SIZE]


def test_mobil_changes_to_a_free_lane_to_pass_a_slow_leader():
    action, memory = drive([EGO, SLOW_AHEAD], desired_speed=30.0)
    assert memory.target_lane[0, 0].item() == 1
    assert action.steer[0, 0].item() > 0  # turning left, towards lane 1
    assert memory.since_change[0, 0].item() == 0


def test_a_vehicle_another_model_drives_occupies_only_the_lane_it_is_in():
    # Vehicle 1, ahead in lane 0, carries a lane-change target into lane 1
    # (the ego's). Driven by IDM it occupies both lanes and the ego brakes;
    # driven by another model it is only in lane 0 and the ego's road is free.
    sim = simulator(ROAD)
    state = VehicleState.from_rows(
        [[0.0, 6.0, 0.0, 25.0, *SIZE], [15.0, 2.0, 0.0, 10.0, *SIZE]], dtype=F64
    )
    obs = sim.observe(state, torch.zeros(1, dtype=torch.int64))
    params = IDMParams.full(state.shape, dtype=F64, desired_speed=30.0)

    def ego_accel(controlled):
        driver = IDMDriver(params, ROAD, controlled=controlled)
        memory = driver.init(obs, None)
        merging = IDMState(torch.tensor([[1, 1]]), memory.since_change)
        return driver.act(obs, merging, None)[0].accel[0, 0].item()

    assert ego_accel(None) < 0 < ego_accel(torch.tensor([True, False]))


def test_mobil_stays_when_the_new_follower_would_have_to_brake_hard():
    fast_behind = [-8.0, 6.0, 0.0, 30.0, *SIZE]
    _, memory = drive([EGO, SLOW_AHEAD, fast_behind], desired_speed=30.0)
    assert memory.target_lane[0, 0].item() == 0


def test_mobil_stays_when_the_other_lane_is_occupied_alongside():
    alongside = [1.0, 6.0, 0.0, 25.0, *SIZE]
    _, memory = drive([EGO, SLOW_AHEAD, alongside], desired_speed=30.0)
    assert memory.target_lane[0, 0].item() == 0


def test_mobil_stays_on_an_empty_road():
    _, memory = drive([EGO], desired_speed=30.0)
    assert memory.target_lane[0, 0].item() == 0


def test_mobil_stays_when_the_gain_is_below_the_threshold():
    _, memory = drive(
        [EGO, SLOW_AHEAD], desired_speed=30.0, lane_change_threshold=100.0
    )
    assert memory.target_lane[0, 0].item() == 0


def test_a_vehicle_on_the_rightmost_lane_never_targets_a_lane_beyond_the_edge():
    slow_ahead_left = [25.0, 6.0, 0.0, 10.0, *SIZE]
    ego_left = [0.0, 6.0, 0.0, 25.0, *SIZE]
    _, memory = drive([ego_left, slow_ahead_left], desired_speed=30.0)
    assert memory.target_lane[0, 0].item() == 0  # moves right, into lane 0
    _, memory = drive([EGO, [25.0, 2.0, 0.0, 10.0, *SIZE], [-30, 6.0, 0, 40, *SIZE]])
    assert memory.target_lane.min().item() >= 0


def simulate(rows, policy=None, horizon=10.0, road=ROAD, **params):
    sim = simulator(road, SimConfig(horizon=horizon))
    state = VehicleState.from_rows(rows, dtype=F64)
    p = IDMParams.full(state.shape, dtype=F64, **params)
    seeds = torch.zeros(1, dtype=torch.int64)
    actors = [IDMDriver(p, road)] + ([] if policy is None else [policy])
    return sim.run(state, actors, seeds, record_trace=True)


def test_the_lane_keeping_controller_settles_on_the_lane_centre():
    res = simulate([[0.0, 3.0, 0.05, 20.0, *SIZE]], desired_speed=20.0)
    y = res.trace.y[0, :, 0]
    assert abs(y[-1].item() - 2.0) < 0.02
    assert abs(res.trace.heading[0, -1, 0].item()) < 0.01
    assert y.min().item() > 1.5  # small overshoot, stays in its lane


def test_a_lane_change_completes_into_the_new_lane():
    res = simulate([EGO, SLOW_AHEAD], desired_speed=30.0, horizon=6.0)
    assert res.trace.y[0, -1, 0].item() == pytest.approx(6.0, abs=0.1)
    assert not res.crash.item() and not res.offroad.item()


def test_a_follower_stops_behind_a_standing_vehicle_without_reversing():
    standing = [0.0, 2.0, 0.0, 0.0, *SIZE]  # the ego, holding still
    follower = [-60.0, 2.0, 0.0, 20.0, *SIZE]
    res = simulate(
        [standing, follower],
        policy=ConstantPolicy(ego_only(2), accel=0.0),
        horizon=15.0,
        lane_change_threshold=1e3,
    )
    assert not res.crash.item()
    assert res.trace.speed[0, :, 1].min().item() >= 0.0
    gap = res.trace.x[0, -1, 0] - res.trace.x[0, -1, 1] - 4.0
    assert 0.0 < gap.item() < 3.0  # about the jam distance s0 = 2 m
    assert res.trace.speed[0, -1, 1].item() < 0.1


def test_lane_changes_are_spaced_by_the_decision_delay():
    sim = simulator(Road(n_lanes=4, lane_width=4.0))
    rows = [[0.0, 2.0, 0.0, 25.0, *SIZE], [25.0, 2.0, 0.0, 10.0, *SIZE]]
    state = VehicleState.from_rows(rows, dtype=F64)
    driver = IDMDriver(
        IDMParams.full(state.shape, dtype=F64, desired_speed=30.0), sim.road
    )
    obs = sim.observe(state, torch.zeros(1, dtype=torch.int64))
    _, memory = driver.act(obs, driver.init(obs, None), None)
    assert memory.target_lane[0, 0].item() == 1
    # Pretend the change is done: the centre is in lane 1 and it is slow ahead again.
    moved = VehicleState.from_rows(
        [[0.0, 6.0, 0.0, 25.0, *SIZE], [25.0, 6.0, 0.0, 10.0, *SIZE]], dtype=F64
    )
    obs = sim.observe(moved, torch.zeros(1, dtype=torch.int64))
    delay = round(LANE_CHANGE_DELAY / 0.1)
    for _ in range(delay - 1):
        _, memory = driver.act(obs, memory, None)
        assert memory.target_lane[0, 0].item() == 1
    _, memory = driver.act(obs, memory, None)
    assert memory.target_lane[0, 0].item() == 2


def test_invalid_parameters_are_rejected_with_the_field_named():
    p = IDMParams.full((1, 2), desired_speed=-1.0)
    with pytest.raises(ValueError, match="desired_speed"):
        p.validate()
    with pytest.raises(TypeError, match="unknown"):
        IDMParams.full((1, 2), desired_sped=3.0)
