import pytest
import torch

from avrisk.agents import (
    ConstantPolicy,
    IDMDriver,
    IDMParams,
    IDMPolicy,
    ego_only,
    get_policy,
    register_policy,
)
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.interfaces import Actor

ROAD = Road(n_lanes=2, lane_width=4.0)


def scene(batch=3):
    rows = [[[0.0, 2.0, 0.0, 20.0, 4.0, 2.0], [30.0, 2.0, 0.0, 15.0, 4.0, 2.0]]] * batch
    return VehicleState.from_rows(rows)


def test_the_bundled_policies_and_drivers_are_actors():
    params = IDMParams.full((3, 2))
    assert isinstance(ConstantPolicy(ego_only(2)), Actor)
    assert isinstance(IDMPolicy(params, ROAD), Actor)
    assert isinstance(IDMDriver(params, ROAD), Actor)
    assert IDMDriver(params, ROAD).controlled.tolist() == [True, True]


def test_an_ego_policy_acts_like_the_driver_of_every_vehicle_and_controls_the_ego():
    state = scene()
    obs = Simulator(ROAD, SimConfig(), measure=MinTTC()).observe(state, torch.arange(3))
    params = IDMParams.full(state.shape)
    policy = IDMPolicy(params, ROAD)
    ego, _ = policy.act(obs, policy.init(obs, None), None)
    assert ego.accel.shape == (3, 2) and policy.controlled.tolist() == [True, False]
    driver = IDMDriver(params, ROAD)
    everyone, _ = driver.act(obs, driver.init(obs, None), None)
    assert torch.equal(everyone.accel, ego.accel)
    held, _ = ConstantPolicy(ego_only(2), accel=1.5, steer=-0.1).act(obs, None, None)
    assert held.accel.tolist() == [[1.5, 1.5]] * 3
    assert held.steer.flatten().tolist() == pytest.approx([-0.1] * 6)


def test_a_policy_plugged_in_as_ego_drives_only_the_ego():
    state = scene(1)
    sim = Simulator(ROAD, SimConfig(horizon=1.0), measure=MinTTC())
    drivers = IDMDriver(IDMParams.full(state.shape), ROAD)
    seeds = torch.zeros(1, dtype=torch.int64)
    base = sim.run(state, [drivers], seeds, record_trace=True)
    ego = ConstantPolicy(ego_only(2), accel=-3.0)
    braking = sim.run(state, [drivers, ego], seeds, record_trace=True)
    assert braking.trace.speed[0, -1, 0].item() == pytest.approx(17.0, rel=1e-5)
    assert torch.equal(braking.trace.x[:, :, 1], base.trace.x[:, :, 1])


def test_policies_are_found_by_name_and_unknown_names_list_the_known_ones():
    constant = get_policy("constant", n_vehicles=3, accel=1.0)
    assert isinstance(constant, ConstantPolicy)
    assert constant.controlled.tolist() == [True, False, False]
    p = get_policy("idm_mobil", params=IDMParams.full((1, 2)), road=ROAD)
    assert isinstance(p, IDMPolicy)
    with pytest.raises(KeyError, match="constant"):
        get_policy("no-such-policy")
    with pytest.raises(ValueError, match="already registered"):
        register_policy("constant", ConstantPolicy)
