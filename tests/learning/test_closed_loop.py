import dataclasses

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.store import load_driver_net
from avrisk.learning.imitation.discriminator import human_transitions
from avrisk.learning.imitation.mgail import Discriminator
from avrisk.learning.prior.bootstrap_heads import centre_heads
from avrisk.learning.replay import replay
from avrisk.learning.train_config import ClosedLoopConfig, TrainConfig
from avrisk.learning.training.closed_loop import (
    _minibatch_weights,
    _stress_seeds,
    closed_loop_finetune,
    closed_loop_loss,
    differentiable_replay,
    simulated_transitions,
    stressed,
)
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


def test_replays_and_training_drive_with_the_guard_when_given_one():
    win = queue_windows(n=6, steps=40, gap0=4.0)
    net = load_driver_net()
    road, seeds = Road(), torch.arange(6, dtype=torch.int64)
    guard = BrakeGuard(2.0, 0.5, hold_floor=True)
    with torch.no_grad():
        alone = differentiable_replay(win, net, road, seeds)
        braked = differentiable_replay(win, net, road, seeds, guard)
    both = torch.ones(2, dtype=torch.bool)
    driver = LearnedDriver(
        net, net.default_xi.expand(6, -1), controlled=both, guard=guard
    )
    plain = replay(win, driver, road, seed=0)
    alive = braked.alive.numpy()
    np.testing.assert_allclose(
        braked.v.numpy()[alive], plain.v[:, 1:][alive], atol=1e-5
    )
    assert int(alone.crash.sum()) > int(braked.crash.sum())
    config = ClosedLoopConfig(iterations=2, batch_windows=4, validate_every=1)
    hist = closed_loop_finetune(load_driver_net(), win, config, seed=1)
    held = closed_loop_finetune(load_driver_net(), win, config, seed=1, guard=guard)
    assert hist[0]["val_crash_rate"] >= held[0]["val_crash_rate"]
    assert hist[0]["val_loss"] != held[0]["val_loss"]


def test_training_with_the_guard_needs_one():
    with pytest.raises(ValueError, match="drive_with_guard"):
        TrainConfig(closed_loop=ClosedLoopConfig(drive_with_guard=True), guard=None)


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


def test_stressed_leaders_brake_harder_and_stop_sooner():
    win = queue_windows(n=3, steps=40)
    harder = stressed(win, 1.5)
    decel, decel_h = np.diff(win.v_l, axis=1), np.diff(harder.v_l, axis=1)
    moving = harder.v_l[:, 1:] > 0
    np.testing.assert_allclose(decel_h[moving], 1.5 * decel[moving])
    assert harder.v_l.min() == 0.0 and np.array_equal(harder.v_l[:, 0], win.v_l[:, 0])
    stop, stop_h = (win.v_l == 0).argmax(1), (harder.v_l == 0).argmax(1)
    assert np.all(stop_h < stop)
    assert np.array_equal(harder.v_f, win.v_f) and np.array_equal(harder.gap, win.gap)


def test_stress_windows_add_barrier_replays_of_harder_emergencies():
    win = queue_windows(n=10, steps=30)
    config = ClosedLoopConfig(
        iterations=2, batch_windows=4, validate_every=1, stress_windows=3
    )
    runs = []
    for _ in range(2):
        net = load_driver_net()
        history = closed_loop_finetune(net, win, config, seed=1)
        runs.append((history, net.default_xi.clone()))
    (hist, xi), (hist2, xi2) = runs
    assert hist == hist2 and torch.equal(xi, xi2)
    assert all("stress_crash_rate" in row for row in hist[1:])
    plain = load_driver_net()
    closed_loop_finetune(
        plain, win, dataclasses.replace(config, stress_windows=0), seed=1
    )
    assert not torch.equal(plain.default_xi, xi)


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
        {"ttc_margin": -1.0},
        {"adversarial_weight": -0.5},
        {"disc_batch": 0},
        {"hard_brake_oversample": 0.5},
        {"stress_windows": -1},
        {"stress_factor": 0.9},
    ],
)
def test_closed_loop_config_refuses_bad_settings(kwargs):
    with pytest.raises(ValueError):
        ClosedLoopConfig(**kwargs)


def test_the_ttc_barrier_acts_on_fast_closing_in_line_and_not_on_slow():
    win = queue_windows(n=2, steps=3)
    trace = differentiable_replay(win, load_driver_net(), Road(), torch.arange(2))
    closing = (trace.v - trace.v_l).detach()
    ttc = trace.gap.detach() / closing
    assert (closing > 0).all()  # the leaders brake harder than the followers
    below = ClosedLoopConfig(ttc_margin=float(ttc.max()) * 1.01)
    above = ClosedLoopConfig(ttc_margin=float(ttc.min()) * 0.99)
    assert closed_loop_loss(trace, win, below)[1]["ttc"] > 0.0
    assert closed_loop_loss(trace, win, above)[1]["ttc"] == 0.0
    off = ClosedLoopConfig(ttc_margin=0.0)
    assert closed_loop_loss(trace, win, off)[1]["ttc"] == 0.0
    passed = type(trace)(**{**trace.__dict__, "in_line": torch.zeros_like(trace.alive)})
    assert closed_loop_loss(passed, win, below)[1]["ttc"] == 0.0
    # Its value is the mean squared excess closing speed over the alive steps.
    excess = torch.relu(closing - trace.gap.detach() / below.ttc_margin)
    expected = float((excess**2).mean())
    assert closed_loop_loss(trace, win, below)[1]["ttc"] == pytest.approx(expected)


def test_mgail_reward_gradient_reaches_every_weight_and_not_the_discriminator():
    win = queue_windows(n=4, steps=20)
    net = load_driver_net()
    trace = differentiable_replay(win, net, Road(), torch.arange(4))
    disc = Discriminator(queue_windows(n=6, steps=20, gap0=8.0), 16, 1e-3, seed=0)
    config = ClosedLoopConfig(
        imitation_weight=0.0,
        offset_weight=0.0,
        safety_weight=0.0,
        ttc_margin=0.0,
        adversarial_weight=1.0,
    )
    loss, parts = closed_loop_loss(trace, win, config, disc)
    assert loss.item() == pytest.approx(-parts["reward"])
    loss.backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name
    assert all(p.grad is None for p in disc.net.parameters())


def test_simulated_transitions_of_a_perfect_replay_are_the_human_transitions():
    win = queue_windows(n=3, steps=10)
    t = torch.as_tensor
    trace = type(
        differentiable_replay(win, load_driver_net(), Road(), torch.arange(3))
    )(
        v=t(win.v_f[:, 1:]),
        v_l=t(win.v_l[:, 1:]),
        gap=t(win.gap[:, 1:]),
        offset=t(win.offset[:, 1:]),
        alive=torch.ones(3, 10, dtype=torch.bool),
        in_line=torch.ones(3, 10, dtype=torch.bool),
        crash=torch.zeros(3, dtype=torch.bool),
    )
    x, valid = simulated_transitions(trace, win)
    assert valid.all()
    torch.testing.assert_close(x.reshape(-1, 5).float(), human_transitions(win))


def test_mgail_training_is_reproducible_and_trains_its_discriminator():
    win = queue_windows(n=10, steps=30)
    config = ClosedLoopConfig(
        iterations=3,
        batch_windows=4,
        validate_every=3,
        validation_fraction=0.3,
        imitation_weight=0.0,
        adversarial_weight=1.0,
        ttc_margin=3.0,
        disc_hidden=16,
        disc_batch=64,
    )
    runs = []
    for _ in range(2):
        net = load_driver_net()
        events = []
        closed_loop_finetune(net, win, config, seed=5, progress=events.append)
        runs.append(([e.metrics for e in events], net.state_dict()))
    (rows, weights), (rows2, weights2) = runs
    assert rows == rows2
    assert all(torch.equal(weights[k], weights2[k]) for k in weights)
    assert all(0.0 <= row["disc_accuracy"] <= 1.0 for row in rows)
    assert all("reward" in row and "ttc" in row for row in rows)


def test_hard_braking_windows_are_drawn_as_often_as_asked():
    steady = queue_windows(n=4, steps=10)
    steady = type(steady)(**{**steady.__dict__, "v_l": np.full((4, 11), 8.0)})
    braking = queue_windows(n=2, steps=10)  # leaders brake at 2-4 m/s^2
    win = type(steady)(
        **{
            k: np.concatenate([getattr(steady, k), getattr(braking, k)])
            for k in steady.__dict__
        }
    )
    assert _minibatch_weights(win, ClosedLoopConfig()) is None
    p = _minibatch_weights(win, ClosedLoopConfig(hard_brake_oversample=5.0))
    np.testing.assert_allclose(p, np.array([1, 1, 1, 1, 5, 5]) / 14)
    gentle = ClosedLoopConfig(hard_brake_oversample=5.0, hard_brake_decel=-5.0)
    np.testing.assert_allclose(_minibatch_weights(win, gentle), np.full(6, 1 / 6))


def test_the_congested_share_of_the_draws_is_as_asked_whatever_the_windows_mix():
    flowing = queue_windows(n=3, steps=10)
    flowing = type(flowing)(**{**flowing.__dict__, "v_l": np.full((3, 11), 8.0)})
    slow = type(flowing)(**{**flowing.__dict__, "v_l": np.full((3, 11), 2.0)})
    win = type(flowing)(
        **{
            k: np.concatenate([getattr(flowing, k), getattr(slow, k)[:1]])
            for k in flowing.__dict__
        }
    )  # three flowing windows, one congested
    p = _minibatch_weights(win, ClosedLoopConfig(congested_share=0.5))
    np.testing.assert_allclose(p, [1 / 6, 1 / 6, 1 / 6, 1 / 2])
    only_flowing = win.take([0, 1, 2])
    p = _minibatch_weights(only_flowing, ClosedLoopConfig(congested_share=0.5))
    np.testing.assert_allclose(p, np.full(3, 1 / 3))
    with pytest.raises(ValueError, match="congested_share"):
        ClosedLoopConfig(congested_share=1.0)


def test_stress_replays_get_noise_of_their_own_only_when_asked():
    config = ClosedLoopConfig(iterations=5, batch_windows=8, stress_windows=4)
    minibatch = {
        it: torch.as_tensor(3 * 1_000_003 + it * 8 + np.arange(8)) for it in range(5)
    }
    shared = _stress_seeds(minibatch[2], 3, 2, 4, config)
    assert shared.tolist() == minibatch[2][7:8].tolist() + [
        int(minibatch[3][k]) for k in range(3)
    ]  # as the shipped files were trained: minibatch windows 7, 8, ...
    own = dataclasses.replace(config, stress_own_noise=True)
    seen = set(torch.cat(list(minibatch.values())).tolist())
    drawn = [_stress_seeds(minibatch[it], 3, it, 4, own).tolist() for it in range(5)]
    flat = [s for row in drawn for s in row]
    assert len(set(flat)) == 20 and not seen & set(flat)
