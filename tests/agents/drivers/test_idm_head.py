import json

import pytest
import torch

from avrisk.agents.drivers.features import FEATURE_INDEX, N_FEATURES
from avrisk.agents.drivers.idm_head import (
    ACCEL_FLOOR,
    INITIAL_PARAMS,
    MAX_LOG_GAP_FACTOR,
    IDMHead,
)
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.agents.idm import idm_acceleration
from avrisk.learning.train_config import TrainConfig


def floored(accel):
    """The head's smooth floor at the simulator's clip."""
    return ACCEL_FLOOR + torch.nn.functional.softplus(accel - ACCEL_FLOOR)


def following(speed, range_ahead, range_rate, length=4.5):
    """Features of vehicles following whatever their front beam hits."""
    speed, range_ahead, range_rate = (
        torch.as_tensor(x, dtype=torch.float32)
        for x in (speed, range_ahead, range_rate)
    )
    shape = torch.broadcast_shapes(speed.shape, range_ahead.shape, range_rate.shape)
    f = torch.zeros(*shape, N_FEATURES)
    f[..., FEATURE_INDEX["length"]] = length
    f[..., FEATURE_INDEX["speed"]] = speed
    f[..., FEATURE_INDEX["range_0"]] = range_ahead
    f[..., FEATURE_INDEX["range_rate_0"]] = range_rate
    return f


def test_an_untrained_head_with_r_zero_is_the_floored_idm_of_the_initial_parameters():
    v0, headway, jam_gap, a, b = (torch.tensor(x) for x in INITIAL_PARAMS)
    speed = torch.tensor([0.0, 6.0, 12.0, 12.0])
    range_ahead = torch.tensor([50.0, 20.0, 12.0, 8.0])
    rate = torch.tensor([0.0, -1.0, -3.0, 2.0])
    with torch.no_grad():
        got = IDMHead().mean_accel(torch.zeros(4), following(speed, range_ahead, rate))
    want = idm_acceleration(
        speed, range_ahead - 2.25, speed + rate, v0, headway, jam_gap, a, b
    )
    torch.testing.assert_close(got, floored(want))


def test_r_scales_the_desired_gap_within_its_bound():
    head = IDMHead()
    f = following(10.0, 30.0, 0.0)
    with torch.no_grad():
        near, far = (head.mean_accel(torch.tensor(r), f) for r in (-1.0, 1.0))
        bound = head.mean_accel(torch.tensor(1e6), f)
    assert far < near  # a longer desired gap brakes at a gap the shorter keeps
    v0, headway, jam_gap, a, b = (torch.tensor(x) for x in INITIAL_PARAMS)
    k = torch.exp(torch.tensor(MAX_LOG_GAP_FACTOR))
    want = idm_acceleration(
        torch.tensor(10.0),
        torch.tensor(27.75),
        torch.tensor(10.0),
        v0,
        k * headway,
        k * jam_gap,
        a,
        b,
    )
    torch.testing.assert_close(bound, floored(want))


@pytest.mark.parametrize("r", [-1e6, -3.0, 0.0, 3.0])
def test_whatever_the_network_says_the_mean_brakes_hard_before_a_vehicle_ahead(r):
    # 0.3 m behind a vehicle, closing at 2 and 8 m/s: the IDM asks far more than
    # the simulator's floor of -9 m/s^2, for any output of the network, and the
    # mean is at that floor
    f = following(torch.tensor([2.0, 8.0]), 2.55, torch.tensor([-2.0, -8.0]))
    with torch.no_grad():
        accel = IDMHead().mean_accel(torch.full((2,), r), f)
    assert ((accel < ACCEL_FLOOR + 0.01) & (accel >= ACCEL_FLOOR)).all()


def test_the_floor_bounds_a_demonstrations_error_and_its_gradient_vanishes():
    # a human who did not brake, 0.5 m behind something in its front beam
    f = following(torch.tensor([10.0]), 2.75, torch.tensor([-5.0]))
    r = torch.zeros(1, requires_grad=True)
    accel = IDMHead().mean_accel(r, f)
    (accel - 0.0).square().sum().backward()
    assert accel.item() >= ACCEL_FLOOR and abs(r.grad.item()) < 1e-6


def test_a_driver_network_with_an_idm_head_saves_and_loads_it():
    torch.manual_seed(0)
    net = DriverNet(head="idm").eval()
    with torch.no_grad():
        net.idm.log_factors.copy_(torch.tensor([0.1, -0.2, 0.3, 0.0, 0.05]))
    feats = following(
        torch.rand(3, 4) * 15, 5 + 40 * torch.rand(3, 4), -torch.rand(3, 4)
    )
    xi = 0.01 * torch.randn(3, XI_DIM) + net.default_xi
    arrays = net.to_arrays()
    assert json.loads(str(arrays["meta"]))["head"] == "idm"
    back = DriverNet.from_arrays(arrays)
    assert back.head_kind == "idm"
    with torch.no_grad():
        assert torch.equal(back(feats, xi).accel_mean, net(feats, xi).accel_mean)
        torch.testing.assert_close(back.idm.params(), net.idm.params())


def test_a_free_head_writes_no_head_and_reads_as_before():
    arrays = DriverNet().to_arrays()
    assert "head" not in json.loads(str(arrays["meta"]))
    assert DriverNet.from_arrays(arrays).head_kind == "free"


def test_an_idm_head_needs_the_features_and_an_unknown_head_is_refused():
    net = DriverNet(head="idm")
    with pytest.raises(ValueError, match="needs the features"):
        net.distribution(torch.zeros(2, 4))
    with pytest.raises(ValueError, match="head must be one of free, idm"):
        DriverNet(head="mlp")
    with pytest.raises(ValueError, match="head must be one of"):
        TrainConfig(head="mlp")
    arrays = net.to_arrays()
    meta = json.loads(str(arrays["meta"]))
    arrays["meta"] = json.dumps({**meta, "head": "import os"})
    with pytest.raises(ValueError, match="head must be one of"):
        DriverNet.from_arrays(arrays)


def test_a_rollouts_idm_outputs_are_bit_identical_alone_and_in_a_batch():
    torch.manual_seed(1)
    net = DriverNet(head="idm").eval()
    feats = following(
        15 * torch.rand(7, 5), 3 + 45 * torch.rand(7, 5), torch.randn(7, 5)
    )
    xi = net.default_xi + 0.01 * torch.randn(7, XI_DIM)
    with torch.no_grad():
        batched = net(feats, xi).accel_mean
        for i in (0, 3, 6):
            assert torch.equal(
                net(feats[i : i + 1], xi[i : i + 1]).accel_mean[0], batched[i]
            )
