import json
import math

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.features import N_FEATURES
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import (
    LOG_VAR_MAX,
    DriverNet,
    row_linear,
)
from avrisk.agents.drivers.sampling import reproducible_exp
from avrisk.agents.drivers.xi import XI_DIM


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    mean = torch.randn(N_FEATURES, generator=g)
    scale = torch.rand(N_FEATURES, generator=g) + 0.5
    return DriverNet(mean, scale, (0.8, 0.01)).eval()


def random_inputs(b, a, seed=0):
    g = torch.Generator().manual_seed(seed)
    feats = 10 * torch.randn(b, a, N_FEATURES, generator=g)
    xi = 0.1 * torch.randn(b, XI_DIM, generator=g)
    return feats, xi


def test_outputs_have_one_gaussian_per_vehicle_and_action(net):
    feats, xi = random_inputs(3, 6)
    dist = net(feats, xi)
    for field in ("accel_mean", "steer_mean", "accel_log_var", "steer_log_var"):
        assert getattr(dist, field).shape == (3, 6)


@pytest.mark.parametrize("b", [1, 2, 7, 33])
def test_a_rollouts_outputs_are_bit_identical_alone_and_in_a_batch(net, b):
    feats, xi = random_inputs(b, 5, seed=b)
    with torch.no_grad():
        batched = net(feats, xi)
        for i in sorted({0, b // 2, b - 1}):
            alone = net(feats[i : i + 1], xi[i : i + 1])
            for field in ("accel_mean", "steer_mean", "accel_log_var", "steer_log_var"):
                assert torch.equal(getattr(alone, field)[0], getattr(batched, field)[i])


def test_permuting_the_batch_permutes_the_outputs_exactly(net):
    feats, xi = random_inputs(9, 4, seed=3)
    perm = torch.randperm(9, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        a = net(feats, xi).accel_mean
        b = net(feats[perm], xi[perm]).accel_mean
    assert torch.equal(a[perm], b)


def test_per_rollout_xi_equals_evaluating_each_rollout_with_its_own_head(net):
    feats, xi = random_inputs(4, 3, seed=5)
    with torch.no_grad():
        batched = net(feats, xi)
        for i in range(4):
            shared = net(feats[i], xi[i])  # one xi for all rows
            assert torch.allclose(shared.accel_mean, batched.accel_mean[i], atol=1e-5)
            assert torch.allclose(
                shared.steer_log_var, batched.steer_log_var[i], atol=1e-5
            )


def test_different_xi_give_different_actions_on_the_same_features(net):
    feats, xi = random_inputs(1, 3, seed=6)
    feats = feats.expand(2, -1, -1)
    xi = torch.stack([xi[0], xi[0] + 0.05])
    with torch.no_grad():
        dist = net(feats, xi)
    assert not torch.equal(dist.accel_mean[0], dist.accel_mean[1])


def test_the_default_head_is_used_when_no_xi_is_given(net):
    feats, _ = random_inputs(2, 3, seed=7)
    with torch.no_grad():
        a = net(feats).accel_mean
        b = net(feats, net.default_xi.expand(2, XI_DIM)).accel_mean
    assert torch.allclose(a, b, atol=1e-6)


def test_row_linear_rows_do_not_depend_on_how_many_rows_there_are():
    g = torch.Generator().manual_seed(0)
    w, bias = torch.randn(200, 51, generator=g), torch.randn(200, generator=g)
    x = torch.randn(120, 51, generator=g)
    full = row_linear(x, w, bias)
    for n in list(range(1, 34)) + [64, 100]:
        for start in (0, 5):
            assert torch.equal(
                row_linear(x[start : start + n], w, bias), full[start : start + n]
            )


def test_log_variances_are_clipped_and_scaled_to_physical_units(net):
    raw = torch.tensor([[1.0, 2.0, 100.0, -100.0]])
    dist = net.distribution(raw)
    s_a, s_s = net.action_scale.tolist()
    assert dist.accel_mean.item() == pytest.approx(s_a)
    assert dist.steer_mean.item() == pytest.approx(2 * s_s)
    assert dist.accel_log_var.item() == pytest.approx(
        LOG_VAR_MAX + 2 * math.log(s_a), rel=1e-5
    )


def test_log_prob_is_the_gaussian_log_density(net):
    feats, xi = random_inputs(2, 3, seed=8)
    with torch.no_grad():
        dist = net(feats, xi)
    a, s = torch.randn(2, 3), 0.01 * torch.randn(2, 3)
    lp_a, lp_s = dist.log_prob(a, s)
    ref_a = torch.distributions.Normal(
        dist.accel_mean, torch.exp(0.5 * dist.accel_log_var)
    )
    ref_s = torch.distributions.Normal(
        dist.steer_mean, torch.exp(0.5 * dist.steer_log_var)
    )
    assert torch.allclose(lp_a, ref_a.log_prob(a), atol=1e-5)
    assert torch.allclose(lp_s, ref_s.log_prob(s), atol=1e-5)


def test_weights_round_trip_through_npz_without_pickle(net, tmp_path):
    net.save(tmp_path / "w.npz")
    back = DriverNet.load(tmp_path / "w.npz")
    feats, xi = random_inputs(2, 2, seed=9)
    with torch.no_grad():
        assert torch.equal(net(feats, xi).steer_mean, back(feats, xi).steer_mean)
    with np.load(tmp_path / "w.npz", allow_pickle=False) as z:
        assert z["fc1.weight"].shape == (200, 51) and z["fc2.weight"].shape == (
            100,
            200,
        )


def test_the_brake_guard_travels_with_the_weights(net, tmp_path):
    assert DriverNet.from_arrays(net.to_arrays()).guard is None
    net.guard = BrakeGuard(3.0, 0.5)
    net.save(tmp_path / "w.npz")
    assert DriverNet.load(tmp_path / "w.npz").guard == BrakeGuard(3.0, 0.5)


@pytest.mark.parametrize(
    "guard",
    [
        {"gap_floor": 3.0},
        {"gap_floor": "3", "engage_decel": 0.5},
        {"gap_floor": -1.0, "engage_decel": 0.5},
        {"gap_floor": 3.0, "engage_decel": 1e999},
        [3.0, 0.5],
    ],
)
def test_a_malformed_saved_guard_is_refused(net, guard):
    arrays = net.to_arrays()
    meta = json.loads(str(arrays["meta"]))
    arrays["meta"] = np.array(json.dumps({**meta, "guard": guard}))
    with pytest.raises(ValueError, match="brake guard|gap_floor|engage_decel"):
        DriverNet.from_arrays(arrays)


def test_weights_of_another_format_version_are_refused(net):
    arrays = net.to_arrays()
    arrays["meta"] = np.array('{"format_version": 99}')
    with pytest.raises(ValueError, match="format"):
        DriverNet.from_arrays(arrays)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_reproducible_exp_matches_torch_exp(dtype):
    x = torch.linspace(-30.0, 30.0, 20001, dtype=dtype)
    rel = (reproducible_exp(x) / torch.exp(x) - 1.0).abs().max().item()
    assert rel < 3e-7


def test_reproducible_exp_of_an_element_does_not_depend_on_its_neighbours():
    x = torch.linspace(-5.0, 5.0, 1001)
    full = reproducible_exp(x)
    assert torch.equal(
        torch.stack([reproducible_exp(x[i : i + 1])[0] for i in range(0, 1001, 97)]),
        full[::97],
    )
