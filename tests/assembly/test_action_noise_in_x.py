"""The learned drivers' action noise as columns of X (``actions: sampled_in_x``)."""

import numpy as np
import pytest
import torch

from avrisk.agents.drivers import XI_DIM, LearnedDriver, load_driver_net
from avrisk.agents.drivers.sampling import DRIVER_NOISE_STREAM, innovations_at
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution, param_layout
from avrisk.rare import FixedCovNormal
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import ScenarioParams, load_spec
from avrisk.tensors.noise import normal


def sampled(name, actions, horizon=1.0):
    """A bundled scenario, shortened, its learned drivers acting on ``actions``."""
    spec = load_spec(name)
    drivers = spec.learned_drivers.model_copy(update={"actions": actions})
    simulation = spec.simulation.model_copy(update={"horizon": horizon})
    return spec.model_copy(
        update={"learned_drivers": drivers, "simulation": simulation}
    )


def draw(spec, n, seed=0):
    x = base_distribution(spec).sample(n, chunk_rng(seed, 0, 0))
    return x, sample_seeds(seed, 0, np.arange(n))


def test_x_gets_one_innovation_per_driver_step_and_action_after_xi():
    spec = sampled("highway_default", "sampled_in_x")
    layout = param_layout(spec)
    # 10 steps x 5 learned drivers x (accel, steer)
    assert spec.noise_dim == layout.noise_dim == 100
    assert layout.dim == 24 + XI_DIM + 100
    assert layout.columns[427:430] == ("xi.403", "noise.0", "noise.1")
    assert layout.noise_slice == slice(428, 528) and layout.unit("noise.99") == "-"
    assert sampled("highway_default", "sampled").noise_dim == 0
    assert param_layout(load_spec("highway_idm")).noise_dim == 0


def test_p0_of_the_innovations_is_a_standard_normal_that_cross_entropy_leaves_alone():
    spec = sampled("highway_default", "sampled_in_x")
    p0 = base_distribution(spec)
    noise = p0.blocks[-1]
    assert isinstance(noise, FixedCovNormal) and noise.dim == 100
    assert not noise.searched_coordinates().any()
    x = p0.sample(20_000, np.random.default_rng(1))[:, 428:]
    assert abs(x.mean()) < 4 / np.sqrt(x.size)
    assert abs(x.var() - 1) < 4 * np.sqrt(2 / x.size)
    np.testing.assert_allclose(
        noise.log_prob(x[:3]), -0.5 * (x[:3] ** 2).sum(1) - 50 * np.log(2 * np.pi)
    )


def test_the_identity_covariance_shortcut_gives_the_general_formulas_bits():
    general = FixedCovNormal(np.full(5, 0.5), cov=np.eye(5))
    general._identity = False
    fast = FixedCovNormal(np.full(5, 0.5), cov=np.eye(5))
    assert fast._identity
    z = np.random.default_rng(2).standard_normal((7, 5))
    x = fast.from_standard_normal(z)
    assert np.array_equal(x, general.from_standard_normal(z))
    assert np.array_equal(fast.to_standard_normal(x), general.to_standard_normal(x))
    assert np.array_equal(fast.log_prob(x), general.log_prob(x))


def test_innovations_equal_to_the_seeds_noise_give_the_seeded_rollout_bit_for_bit():
    seeded = sampled("highway_default", "sampled")
    in_x = sampled("highway_default", "sampled_in_x")
    x, seeds = draw(seeded, 4)
    steps, drivers = in_x.simulation.n_steps, np.array(in_x.learned_slots)
    z = torch.stack(
        [
            normal(torch.as_tensor(seeds), t, DRIVER_NOISE_STREAM, (6, 2))
            for t in range(steps)
        ],
        dim=1,
    )  # (B, T, A, 2), the simulator's draws for the drivers' stream
    noise = z[:, :, drivers].reshape(4, -1).double().numpy()
    x_in = np.concatenate([x, noise], axis=1)
    a = ScenarioSimulator(seeded).rollout(x, seeds, record_trace=True)
    b = ScenarioSimulator(in_x).rollout(x_in, seeds + 1, record_trace=True)
    assert torch.equal(a.trace.x, b.trace.x) and torch.equal(a.f, b.f)
    assert not torch.equal(
        a.trace.x,
        ScenarioSimulator(in_x)
        .rollout(x_in[[1, 0, 3, 2]], seeds, record_trace=True)
        .trace.x,
    )


def test_with_innovations_in_x_a_rollout_is_a_function_of_its_row_alone():
    spec = sampled("highway_default", "sampled_in_x", horizon=1.5)
    x, seeds = draw(spec, 5)
    sim = ScenarioSimulator(spec)
    together = sim.rollout(x, seeds, record_trace=True).trace.x
    alone = sim.rollout(x[3:4], seeds[:1] + 99, record_trace=True).trace.x
    assert torch.equal(together[3], alone[0])
    other = x[3:4].copy()
    other[0, 428 + 2 * 5 * 4] += 2.0  # the first driver's acceleration at step 4
    moved = sim.rollout(other, seeds[3:4], record_trace=True).trace.x
    # The state after step 4 (trace index 5) is the first to respond; the
    # noise is autocorrelated, so the later steps' actions move with it.
    assert torch.equal(moved[0, :5], alone[0, :5])
    assert (moved[0, 5:, 1] != alone[0, 5:, 1]).all()
    assert torch.equal(
        moved[0, :, [0, 2, 3, 4, 5]][:6], alone[0, :, [0, 2, 3, 4, 5]][:6]
    )


def test_a_lane_changing_scenario_takes_its_innovations_from_x_too():
    spec = sampled("highway_lane_changes", "sampled_in_x")
    x, seeds = draw(spec, 3)
    sim = ScenarioSimulator(spec)
    assert sim.rollout(x, seeds).f.shape == (3,)
    params = ScenarioParams.from_flat(x, sim.layout)
    assert params.noise.shape == (3, spec.noise_dim)


def test_the_driver_refuses_innovations_it_cannot_use():
    net = load_driver_net()
    everyone = torch.ones(2, dtype=torch.bool)
    with pytest.raises(ValueError, match="stochastic=True"):
        LearnedDriver(net, controlled=everyone, stochastic=False, noise_steps=3)
    driver = LearnedDriver(net, controlled=everyone, noise_steps=3)
    assert driver.noise is None and driver.params_dim == XI_DIM + 12
    obs = type("Obs", (), {"state": type("S", (), {"batch_size": 2})()})()
    with pytest.raises(ValueError, match=r"shape \(B, 416\)"):
        driver.init(obs, torch.zeros(2, XI_DIM))


def test_innovations_at_takes_each_rollouts_own_step():
    block = torch.arange(2 * 3 * 1 * 2, dtype=torch.float32).reshape(2, 3, 1, 2)
    assert torch.equal(innovations_at(block, 1), block[:, 1])
    both = innovations_at(block, torch.tensor([2, 0]))
    assert torch.equal(both, torch.stack([block[0, 2], block[1, 0]]))
