import pytest
import torch

from avrisk.agents import (
    ConstantPolicy,
    DriverModel,
    IDMDriver,
    IDMParams,
    IDMPolicy,
    Policy,
    get_policy,
    register_policy,
)
from avrisk.sim import Road, SimConfig, Simulator, VehicleState

ROAD = Road(n_lanes=2, lane_width=4.0)


def scene(batch=3):
    rows = [[[0.0, 2.0, 0.0, 20.0, 4.0, 2.0], [30.0, 2.0, 0.0, 15.0, 4.0, 2.0]]] * batch
    return VehicleState.from_rows(rows)


def test_the_bundled_policies_and_drivers_satisfy_their_protocols():
    params = IDMParams.full((3, 2))
    assert isinstance(ConstantPolicy(), Policy)
    assert isinstance(IDMPolicy(params, ROAD), Policy)
    assert isinstance(IDMDriver(params, ROAD), DriverModel)


def test_an_ego_policy_returns_one_action_per_rollout_and_a_driver_one_per_vehicle():
    state = scene()
    obs = Simulator(ROAD, SimConfig()).observe(state, torch.arange(3))
    params = IDMParams.full(state.shape)
    ego, _ = IDMPolicy(params, ROAD).act(obs, IDMPolicy(params, ROAD).init(obs))
    assert ego.accel.shape == (3,) and ego.steer.shape == (3,)
    driver = IDMDriver(params, ROAD)
    everyone, _ = driver.act(obs, driver.init(obs))
    assert everyone.accel.shape == (3, 2)
    assert torch.equal(everyone.accel[:, 0], ego.accel)
    held, _ = ConstantPolicy(accel=1.5, steer=-0.1).act(obs, None)
    assert held.accel.tolist() == [1.5] * 3 and held.steer.tolist() == pytest.approx(
        [-0.1] * 3
    )


def test_a_policy_plugged_in_as_ego_drives_only_the_ego():
    state = scene(1)
    sim = Simulator(ROAD, SimConfig(horizon=1.0))
    params = IDMParams.full(state.shape)
    base = sim.rollout(
        state, params, torch.zeros(1, dtype=torch.int64), record_trace=True
    )
    braking = sim.rollout(
        state, params, torch.zeros(1, dtype=torch.int64), record_trace=True,
        ego_policy=ConstantPolicy(accel=-3.0),
    )  # fmt: skip
    assert braking.trace.speed[0, -1, 0].item() == pytest.approx(17.0, rel=1e-5)
    assert torch.equal(braking.trace.x[:, :, 1], base.trace.x[:, :, 1])


def test_policies_are_found_by_name_and_unknown_names_list_the_known_ones():
    assert isinstance(get_policy("constant", accel=1.0), ConstantPolicy)
    p = get_policy("idm_mobil", params=IDMParams.full((1, 2)), road=ROAD)
    assert isinstance(p, IDMPolicy)
    with pytest.raises(KeyError, match="constant"):
        get_policy("no-such-policy")
    with pytest.raises(ValueError, match="already registered"):
        register_policy("constant", ConstantPolicy)
