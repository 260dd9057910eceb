import pytest
import torch

from avrisk.agents.drivers.driver import LearnedDriver, LearnedEgoPolicy
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.sampling import (
    DRIVER_NOISE_STREAM,
    EGO_NOISE_STREAM,
    ar1_noise,
    sample_actions,
)
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.agents.policy import get_policy
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.interfaces import Actor, NoiseRequest
from avrisk.tensors.noise import normal

ROAD = Road(n_lanes=3)
ALL3 = torch.tensor([True, True, True])


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    net = DriverNet(action_scale=(0.5, 0.005)).eval()
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(0.3)
    return net


def scenes(b):
    g = torch.Generator().manual_seed(b)
    rows = []
    for _ in range(b):
        x = torch.tensor([0.0, 25.0, 10.0]) + 5 * torch.rand(3, generator=g)
        y = torch.tensor([5.55, 5.55, 1.85]) + 0.2 * torch.randn(3, generator=g)
        v = 15 + 5 * torch.rand(3, generator=g)
        rows.append([[x[i], y[i], 0.0, v[i], 4.8, 1.9] for i in range(3)])
    return VehicleState.from_rows(torch.tensor(rows).tolist())


def sim(horizon=1.0):
    return Simulator(ROAD, SimConfig(horizon=horizon), measure=MinTTC(n_rays=8))


@pytest.mark.parametrize("stochastic", [False, True])
def test_a_rollout_is_bit_identical_alone_and_in_a_batch(net, stochastic):
    b = 5
    state = scenes(b)
    xi = net.default_xi + 0.02 * torch.randn(
        b, XI_DIM, generator=torch.Generator().manual_seed(1)
    )
    seeds = torch.arange(100, 100 + b)
    driver = LearnedDriver(net, controlled=ALL3, stochastic=stochastic)
    batch = sim().run(state, [driver], seeds, params=[xi], record_trace=True)
    for i in (0, 3):
        alone = sim().run(
            state[i : i + 1],
            [driver],
            seeds[i : i + 1],
            params=[xi[i : i + 1]],
            record_trace=True,
        )
        assert torch.equal(alone.trace.x[0], batch.trace.x[i])
        assert torch.equal(alone.trace.y[0], batch.trace.y[i])
        assert torch.equal(alone.f[0], batch.f[i])
    # xi as the actor's parameter block or given to the constructor: the same.
    built = LearnedDriver(net, xi, controlled=ALL3, stochastic=stochastic)
    again = sim().run(state, [built], seeds, record_trace=True)
    assert torch.equal(again.trace.x, batch.trace.x)


def test_the_drivers_ask_the_simulator_for_noise_only_when_they_sample(net):
    driver = LearnedDriver(net, controlled=ALL3)
    assert isinstance(driver, Actor) and isinstance(LearnedEgoPolicy(net, 3), Actor)
    assert driver.noise == NoiseRequest(DRIVER_NOISE_STREAM, (3, 2), torch.float32)
    assert LearnedDriver(net, controlled=ALL3, stochastic=False).noise is None
    ego = LearnedEgoPolicy(net, 3, stochastic=True)
    assert ego.noise == NoiseRequest(EGO_NOISE_STREAM, (2,), torch.float32)
    assert LearnedEgoPolicy(net, 3).noise is None


def test_sampled_actions_depend_on_the_seed_and_means_do_not(net):
    state = scenes(1).map(lambda t: t.expand(2, -1).contiguous())
    obs = sim().observe(state, torch.tensor([1, 2]))
    dist = LearnedDriver(net, controlled=ALL3).distribution(obs, net.default_xi)
    z = normal(obs.seeds, 0, 7, (3, 2))
    eps = ar1_noise(None, z, net.noise_correlation)
    a_mean, _ = sample_actions(dist, None)
    a_rand, _ = sample_actions(dist, eps)
    assert torch.equal(a_mean[0], a_mean[1])
    assert not torch.equal(a_rand[0], a_rand[1])


def test_correlated_noise_has_a_standard_normal_marginal_and_the_given_correlation():
    # 20000 draws: the standard error of a correlation or variance is < 0.011,
    # so 0.05 is a > 4.5 sigma tolerance.
    seeds = torch.arange(20_000)
    rho = torch.tensor([0.9, 0.0])
    first = ar1_noise(None, normal(seeds, 0, 3, (2,)), rho)
    second = ar1_noise(first, normal(seeds, 1, 3, (2,)), rho)
    for k, r in enumerate(rho.tolist()):
        assert second[:, k].var().item() == pytest.approx(1.0, abs=0.05)
        corr = torch.corrcoef(torch.stack([first[:, k], second[:, k]]))[0, 1]
        assert corr.item() == pytest.approx(r, abs=0.05)


def test_a_braking_driver_stops_rather_than_reverses(net):
    braking = DriverNet(action_scale=(1.0, 0.01)).eval()
    braking.load_state_dict(net.state_dict())
    with torch.no_grad():
        braking.last.bias[0] = -20.0  # mean acceleration -20 m/s^2
    state = VehicleState.from_rows([[0.0, 5.55, 0.0, 3.0, 4.8, 1.9]])
    driver = LearnedDriver(braking, controlled=torch.tensor([True]), stochastic=False)
    res = sim(horizon=2.0).run(state, [driver], torch.tensor([0]), record_trace=True)
    assert res.trace.speed.min().item() >= 0.0
    assert res.trace.speed[0, -1, 0].item() == 0.0
    assert not bool(res.reversing[0])


def test_the_lidar_ego_controls_vehicle_zero_only(net):
    state = scenes(4)
    obs = sim().observe(state, torch.arange(4))
    ego = get_policy("lidar_imitation", net=net, n_vehicles=3)
    assert isinstance(ego, LearnedEgoPolicy)
    assert ego.controlled.tolist() == [True, False, False]
    action, _ = ego.act(obs, ego.init(obs, None), None)
    assert action.accel.shape == (4, 3) and action.steer.shape == (4, 3)
    driver = LearnedDriver(net, controlled=ALL3, stochastic=False)
    full = driver.act(obs, driver.init(obs, None), None)[0]
    assert torch.allclose(action.accel[:, 0], full.accel[:, 0], atol=1e-6)


def test_per_rollout_xi_must_match_the_batch(net):
    obs = sim().observe(scenes(3), torch.arange(3))
    driver = LearnedDriver(net, controlled=ALL3)
    with pytest.raises(ValueError, match="xi for 2 rollouts"):
        driver.init(obs, torch.zeros(2, XI_DIM))
    with pytest.raises(ValueError, match="xi for 2 rollouts"):
        LearnedDriver(net, torch.zeros(2, XI_DIM), controlled=ALL3).init(obs, None)
    with pytest.raises(ValueError, match="404"):
        LearnedDriver(net, torch.zeros(3, 10), controlled=ALL3)


def test_a_guarded_driver_brakes_for_a_stopped_vehicle_ahead_and_is_unchanged_elsewhere(
    net,
):
    # Vehicle 0 closes at 15 m/s on vehicle 1, stopped 30 m ahead in its lane;
    # vehicle 2 drives alone in the next lane.
    rows = [
        [0.0, 5.55, 0.0, 15.0, 4.8, 1.9],
        [30.0, 5.55, 0.0, 0.0, 4.8, 1.9],
        [-40.0, 1.85, 0.0, 15.0, 4.8, 1.9],
    ]
    state = VehicleState.from_rows([rows])
    seeds = torch.tensor([3])
    plain = LearnedDriver(net, controlled=ALL3, stochastic=False)
    guarded = LearnedDriver(
        net, controlled=ALL3, stochastic=False, guard=BrakeGuard(2.0, 1.0)
    )
    a = sim(horizon=0.1).run(state, [plain], seeds, record_trace=True).trace
    b = sim(horizon=0.1).run(state, [guarded], seeds, record_trace=True).trace
    # 25.2 m of bumper gap, 23.2 m of room: 15^2 / 46.4 = 4.85 m/s^2 needed
    braked = (b.speed[0, 1, 0] - b.speed[0, 0, 0]) / 0.1
    assert braked.item() == pytest.approx(-225.0 / 46.4, rel=1e-4)
    assert (a.speed[0, 1, 0] - a.speed[0, 0, 0]).item() / 0.1 > -1.0
    assert torch.equal(a.x[0, :, 2], b.x[0, :, 2])  # nothing ahead: no change
    assert torch.equal(a.speed[0, :, 1], b.speed[0, :, 1])
