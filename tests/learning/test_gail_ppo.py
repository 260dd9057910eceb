"""GAIL with PPO, the tried fine-tune that lives beside its benchmark.

``benchmarks/gail_ppo.py`` is not in the package; it is loaded from its file,
as ``benchmarks/gail_realism.py`` imports it.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
from avrisk.learning.imitation.discriminator import mlp
from tests.learning.recorded_windows import recorded_windows


def _load_gail_ppo():
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "gail_ppo.py"
    spec = importlib.util.spec_from_file_location("gail_ppo", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


gail_ppo = _load_gail_ppo()
GailConfig = gail_ppo.GailConfig
PPOBatch = gail_ppo.PPOBatch
accel_log_prob = gail_ppo.accel_log_prob
gae = gail_ppo.gae
gail_finetune = gail_ppo.gail_finetune
ppo_update = gail_ppo.ppo_update
translate_prior = gail_ppo.translate_prior

pytestmark = pytest.mark.usefixtures("one_thread")

STEER_ROWS = [1, 3]


def test_accel_log_prob_is_the_ar1_trajectory_density():
    torch.manual_seed(0)
    net = DriverNet(noise_correlation=(0.5, 0.0), noise_scale=(0.7, 1.0))
    hidden = torch.rand(2, 3, 100)
    accel = torch.randn(2, 3)
    with torch.no_grad():
        log_p, _ = accel_log_prob(net, hidden, accel)
        dist = net.distribution(net.head(hidden))
    std = 0.7 * torch.exp(0.5 * dist.accel_log_var)
    lag = torch.arange(3)
    corr = 0.5 ** (lag[:, None] - lag[None, :]).abs().double()
    for w in range(2):
        cov = std[w, :, None].double() * corr * std[w, None, :].double()
        mvn = torch.distributions.MultivariateNormal(dist.accel_mean[w].double(), cov)
        assert float(log_p[w].sum()) == pytest.approx(
            float(mvn.log_prob(accel[w].double())), rel=1e-5
        )


def test_gae_stops_at_the_last_step():
    adv = gae(torch.ones(1, 3), torch.zeros(1, 3), torch.tensor([1]), 0.5, 1.0)
    assert adv.tolist() == [[1.5, 1.0, 0.0]]


def test_ppo_moves_the_mean_acceleration_towards_a_toy_reward():
    torch.manual_seed(0)
    net = DriverNet()
    steer_before = net.last.weight[STEER_ROWS].clone()
    value_net = mlp(4, 16)
    config = GailConfig(ppo_epochs=4, ppo_windows=16, policy_lr=3e-3)
    policy_opt = torch.optim.Adam([net.last.weight, net.last.bias], lr=3e-3)
    value_opt = torch.optim.Adam(value_net.parameters(), lr=1e-2)
    gen = torch.Generator().manual_seed(0)
    hidden = torch.rand(64, 8, 100, generator=gen)
    state = torch.zeros(64, 8, 4)
    last = torch.full((64,), 7)

    def mean_accel():
        with torch.no_grad():
            return float(net.distribution(net.head(hidden)).accel_mean.mean())

    start = mean_accel()
    for _ in range(15):
        with torch.no_grad():
            dist = net.distribution(net.head(hidden))
            accel = dist.accel_mean + torch.exp(0.5 * dist.accel_log_var) * torch.randn(
                64, 8, generator=gen
            )
            old_log_p, _ = accel_log_prob(net, hidden, accel)
            values = value_net(state).squeeze(-1)
            adv = gae(-((accel - 2.0) ** 2), values, last, 0.0, 0.0)
        batch = PPOBatch(
            hidden=hidden,
            accel=accel,
            old_log_p=old_log_p,
            advantages=adv,
            returns=adv + values,
            state=state,
            valid=torch.ones(64, 8, dtype=torch.bool),
        )
        ppo_update(net, value_net, batch, policy_opt, value_opt, config, gen)
    assert abs(start - 2.0) > 1.5
    assert abs(mean_accel() - 2.0) < 0.5 * abs(start - 2.0)
    assert torch.equal(net.last.weight[STEER_ROWS], steer_before)


def windows(n=4, steps=20):
    t = np.arange(steps + 1) * 0.1
    v_l = np.stack([10 + 2 * np.sin(t + k) for k in range(n)])
    return recorded_windows(
        np.full((n, steps + 1), 10.0), v_l, np.full((n, steps + 1), 15.0)
    )


def test_a_tiny_gail_run_is_reproducible_and_tunes_only_the_acceleration_head():
    bc = load_driver_net()
    original = bc.last.weight.clone()
    config = GailConfig(
        iterations=2, windows_per_iter=3, disc_batch=64, ppo_windows=2, ppo_epochs=1
    )
    events = []
    a, hist_a = gail_finetune(bc, windows(), config, seed=5, progress=events.append)
    b, hist_b = gail_finetune(bc, windows(), config, seed=5)
    assert hist_a == hist_b and len(hist_a) == 2
    assert [e.stage for e in events] == ["gail", "gail"]
    assert 0.0 <= hist_a[-1]["disc_accuracy"] <= 1.0
    assert 0.0 <= hist_a[-1]["collision_rate"] <= 1.0
    for name, p in a.state_dict().items():
        assert torch.equal(p, b.state_dict()[name]), name
    assert torch.equal(bc.last.weight, original)  # the input is not modified
    moved = (a.last.weight - original).abs().amax(1)
    assert moved[0] > 0 and moved[2] > 0 and moved[STEER_ROWS].max() == 0
    assert torch.equal(a.fc1.weight, bc.fc1.weight)
    prior = load_xi_prior()
    shifted = translate_prior(prior, bc, a)
    shift = (a.default_xi - bc.default_xi).double().numpy()
    assert np.allclose(shifted.mean - prior.mean, shift)
    assert np.allclose(shifted.members - prior.members, shift)
