import numpy as np
import torch

from avrisk.agents.drivers.features import FEATURE_INDEX, N_FEATURES
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.learning.imitation.behaviour_cloning import (
    behaviour_cloning,
    fit_action_scale,
    fit_input_normalization,
)
from avrisk.learning.imitation.demonstrations import (
    SOURCE_I80,
    SOURCE_IDM,
    Demonstrations,
)
from avrisk.learning.imitation.loss import imitation_nll
from avrisk.learning.prior.bootstrap_heads import bootstrap_heads


def synthetic_demos(n=3000, seed=0):
    """Accel follows the gap ahead, steer corrects the lateral offset (plus noise)."""
    rng = np.random.default_rng(seed)
    f = rng.normal(0.0, 1.0, (n, N_FEATURES)).astype(np.float32)
    f[:, FEATURE_INDEX["range_0"]] = rng.uniform(5, 50, n)
    f[:, FEATURE_INDEX["lateral_offset"]] = rng.uniform(-1, 1, n)
    f[:, FEATURE_INDEX["collided"]] = 0.0
    accel = 0.05 * (f[:, FEATURE_INDEX["range_0"]] - 25) + 0.1 * rng.normal(size=n)
    steer = -0.02 * f[:, FEATURE_INDEX["lateral_offset"]] + 0.002 * rng.normal(size=n)
    idm = np.arange(n) % 3 == 0
    return Demonstrations(
        features=f,
        accel=accel.astype(np.float32),
        steer=steer.astype(np.float32),
        accel_weight=np.where(idm, 0.25, 1.0).astype(np.float32),
        steer_weight=np.where(idm, 1.0, 0.0).astype(np.float32),
        episode=(np.arange(n) // 50).astype(np.int64),
        source=np.where(idm, SOURCE_IDM, SOURCE_I80).astype(np.int8),
    )


def fresh_net(demos):
    torch.manual_seed(0)
    mean, scale = fit_input_normalization(demos.features)
    return DriverNet(mean, scale, fit_action_scale(demos))


def test_a_short_behaviour_cloning_run_lowers_the_imitation_loss():
    demos = synthetic_demos()
    net = fresh_net(demos)
    before = imitation_nll(net, demos)
    history = behaviour_cloning(
        net, demos, epochs=3, batch_size=256, lr=3e-3, val=demos
    )
    after = imitation_nll(net, demos)
    assert after["loss"] < before["loss"] - 0.5
    assert after["ngsim_i80_pairs/accel"] < before["ngsim_i80_pairs/accel"]
    assert after["sim_idm_mobil/steer"] < before["sim_idm_mobil/steer"]
    assert "ngsim_i80_pairs/steer" not in after  # no steering targets there
    assert [h["epoch"] for h in history] == [1.0, 2.0, 3.0]
    assert history[-1]["val/loss"] == after["loss"]


def test_indicators_are_not_standardised():
    mean, scale = fit_input_normalization(synthetic_demos(200).features)
    k = FEATURE_INDEX["collided"]
    assert (mean[k], scale[k]) == (0.0, 1.0)


def test_bootstrap_heads_are_comparable_members_near_the_shared_head():
    demos = synthetic_demos(1500)
    net = fresh_net(demos)
    behaviour_cloning(net, demos, epochs=1, batch_size=256, lr=3e-3)
    trunk_before = net.fc1.weight.detach().clone()
    heads, history = bootstrap_heads(net, demos, 4, epochs=2, batch_size=512, seed=1)
    assert heads.shape == (4, XI_DIM) and len(history) == 2
    assert torch.equal(net.fc1.weight, trunk_before)  # the trunk is frozen
    assert np.unique(heads, axis=0).shape[0] == 4  # resamples differ
    spread = np.abs(heads - net.default_xi.numpy()).max()
    assert 0 < spread < 0.5
    again, _ = bootstrap_heads(net, demos, 4, epochs=2, batch_size=512, seed=1)
    assert np.array_equal(heads, again)  # seeded
