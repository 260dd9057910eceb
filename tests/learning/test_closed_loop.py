import numpy as np
import pytest
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.store import load_driver_net
from avrisk.learning.bootstrap_heads import centre_heads
from avrisk.learning.closed_loop import (
    closed_loop_finetune,
    closed_loop_loss,
    differentiable_replay,
)
from avrisk.learning.replay import replay
from avrisk.learning.train_config import ClosedLoopConfig
from avrisk.sim import Road
from tests.learning.recorded_windows import recorded_windows

pytestmark = pytest.mark.usefixtures("one_thread")


def queue_windows(n=6, steps=40, gap0=6.0):
    """Leaders braking from 8 m/s to a stop at 2-4 m/s^2; the human stops 3 m behind."""
    t = np.arange(steps + 1) * 0.1
    decel = np.linspace(2.0, 4.0, n)[:, None]
    v_l = np.maximum(8.0 - decel * t, 0.0)
    v_f = np.maximum(8.0 - 0.8 * decel * t, 0.0)
    gap = gap0 + np.cumsum(np.c_[np.zeros(n), (v_l - v_f)[:, 1:]] * 0.1, axis=1)
    return recorded_windows(v_f, v_l, gap)


def test_the_differentiable_replay_is_the_replay_of_the_simulator_with_gradient():
    net = load_driver_net()
    win = queue_windows()
    road = Road()
    seeds = torch.arange(len(win), dtype=torch.int64) + 11 * 1_000_003
    trace = differentiable_replay(win, net, road, seeds)
    both = torch.ones(2, dtype=torch.bool)
    xi = net.default_xi.expand(len(win), -1)
    plain = replay(win, LearnedDriver(net, xi, controlled=both), road, seed=11)
    alive = trace.alive.numpy()
    np.testing.assert_allclose(
        trace.v.detach().numpy()[alive], plain.v[:, 1:][alive], atol=1e-5
    )
    np.testing.assert_allclose(
        trace.gap.detach().numpy()[alive], plain.gap[:, 1:][alive], atol=1e-4
    )
    assert np.array_equal(trace.crash.numpy(), plain.crash)
    loss, _ = closed_loop_loss(trace, win, ClosedLoopConfig())
    loss.backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_the_barrier_acts_only_below_the_margin_and_in_line():
    win = queue_windows(n=2, steps=3)
    net = load_driver_net()
    trace = differentiable_replay(win, net, Road(), torch.arange(2))
    far = ClosedLoopConfig(gap_margin=0.0)
    near = ClosedLoopConfig(gap_margin=50.0)
    assert closed_loop_loss(trace, win, far)[1]["safety"] == 0.0
    assert closed_loop_loss(trace, win, near)[1]["safety"] > 0.0
    passed = type(trace)(**{**trace.__dict__, "in_line": torch.zeros_like(trace.alive)})
    assert closed_loop_loss(passed, win, near)[1]["safety"] == 0.0


def test_closed_loop_training_is_reproducible_and_keeps_the_best_validation():
    win = queue_windows(n=10, steps=30)
    config = ClosedLoopConfig(
        iterations=4,
        batch_windows=4,
        lr=1e-3,
        validate_every=2,
        validation_fraction=0.3,
    )
    runs = []
    for _ in range(2):
        net = load_driver_net()
        events = []
        history = closed_loop_finetune(net, win, config, seed=3, progress=events.append)
        runs.append((history, net.default_xi.clone()))
    (hist, xi), (hist2, xi2) = runs
    assert hist == hist2 and torch.equal(xi, xi2)
    assert [e.stage for e in events] == ["closed_loop"] * 4
    assert [row["iteration"] for row in hist] == [0.0, 2.0, 4.0]
    best = min(hist, key=lambda row: row["val_loss"])
    if best["iteration"] == 0.0:
        assert torch.equal(xi, load_driver_net().default_xi)
    else:
        assert not torch.equal(xi, load_driver_net().default_xi)


def test_closed_loop_training_teaches_a_crashing_driver_to_stop_in_time():
    win = queue_windows(n=12, steps=40, gap0=4.0)
    net = load_driver_net()
    road = Road()
    seeds = torch.arange(len(win), dtype=torch.int64)
    with torch.no_grad():
        before = differentiable_replay(win, net, road, seeds)
    config = ClosedLoopConfig(
        iterations=30, batch_windows=12, lr=1e-3, validate_every=10, safety_weight=10.0
    )
    closed_loop_finetune(net, win, config, seed=0)
    with torch.no_grad():
        after = differentiable_replay(win, net, road, seeds)
    crash_before = int(before.crash.sum())
    assert crash_before >= 3
    assert int(after.crash.sum()) < crash_before


def test_centred_heads_keep_their_spread_around_the_network_head():
    net = load_driver_net()
    rng = np.random.default_rng(0)
    heads = rng.normal(size=(5, net.default_xi.numel()))
    centred = centre_heads(heads, net)
    np.testing.assert_allclose(centred.mean(0), net.default_xi.double().numpy())
    np.testing.assert_allclose(centred - centred.mean(0), heads - heads.mean(0))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"iterations": -1},
        {"batch_windows": 0},
        {"window_steps": 0},
        {"validation_fraction": 1.0},
    ],
)
def test_closed_loop_config_refuses_bad_settings(kwargs):
    with pytest.raises(ValueError):
        ClosedLoopConfig(**kwargs)
