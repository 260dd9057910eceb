"""Closed-loop training: back-propagation through replays of human car following.

Behaviour cloning fits one-step actions; in closed loop the learned drivers
drift into states the data never show and, in stop-and-go queues, brake too
late (rear-end collisions). This stage trains the whole driver network on
what it does in closed loop, differentiating through the simulator's own
functional step (:meth:`avrisk.sim.Simulator.step`, autograd-ready; no second
simulator), as the paper's model-based GAIL differentiates through a model
and as differentiable-simulation imitation does (e.g. Scheel et al. 2021,
"Urban Driver"). Per iteration::

    replay a minibatch of *training* car-following windows of T steps: the
        follower (the network, actions sampled with the deployed AR(1) noise,
        reparameterised) starts from the recorded state; the leader replays
        its recorded speed profile (:mod:`avrisk.learning.replay`)
    loss = imitation + safety - adversarial
        imitation: Huber distance of the simulated follower's speed, gap and
            (lateral windows) lane offset to the human's, per step, each
            divided by a scale (1 m/s, 2 m, 0.3 m)
        safety: (gap_margin - gap)_+^2 per step [m^2] while the two overlap
            laterally: a barrier that grows before contact (a crash stops the
            rollout, and no gradient flows through the steps after it); and,
            if ttc_margin > 0, (closing speed - gap / ttc_margin)_+^2
            [m^2/s^2]: a barrier on a time to collision under ttc_margin,
            which acts while the follower closes in fast, before the gap is
            short
        adversarial (MGAIL, if adversarial_weight > 0): the mean reward
            -log(1 - D(x_t)) of a discriminator D of human vs simulated
            transitions x_t (:mod:`avrisk.learning.imitation.mgail`), updated on the
            same minibatch just before; its gradient flows through the
            simulated transitions into the policy, as in model-based GAIL
            (Baram et al. 2017) with the simulator as the model, and the
            barriers play the part of RAIL's collision penalty
    stress (if stress_windows > 0): that many hard-braking training windows
        (drawn with replacement), their leaders braking stress_factor times
        as hard (:func:`stressed`), replayed under the barriers alone (their
        recorded follower no longer belongs to them) and added to the loss: the
        emergencies of the held-out data (leaders braking at -3 m/s^2 into
        a standing queue) are harder than nearly all training windows
    one Adam step on every weight of the network (trunk and shared head)

With ``drive_with_guard`` the minibatch and validation replays drive with the
emergency brake the weights will carry (:mod:`avrisk.agents.drivers.guard`),
so that the network learns the braked driver's following; the stress replays
drive the network alone, so that it learns to stop in their emergencies by
itself rather than leave them to the brake.

Early stopping on validation windows (a fixed part of the training windows,
chosen by seed): the weights of the iteration with the lowest validation
loss are kept; the adversarial term is left out of it, as its discriminator
moves from one iteration to the next. The noise buffers
(``noise_correlation``, ``noise_scale``) are kept as calibrated before.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import pack_xi
from avrisk.learning.imitation.discriminator import transition_features
from avrisk.learning.imitation.mgail import Discriminator
from avrisk.learning.ngsim.samples import DEFAULT_WIDTH
from avrisk.learning.replay import (
    BANDS,
    DT,
    CarFollowingWindows,
    replay_setup,
    window_bands,
)
from avrisk.learning.train_config import ClosedLoopConfig, Progress, TrainEvent
from avrisk.sim import Road

__all__ = [
    "closed_loop_finetune",
    "closed_loop_loss",
    "differentiable_replay",
    "simulated_transitions",
    "split_windows",
    "stressed",
]


#: Scales of the imitation terms: speed [m/s], gap [m], lane offset [m].
SPEED_SCALE, GAP_SCALE, OFFSET_SCALE = 1.0, 2.0, 0.3


@dataclass(frozen=True)
class ClosedLoopTrace:
    """The simulated follower of every window, with gradient.

    Attributes
    ----------
    v, gap, offset : Tensor of shape (W, T)
        Speed [m/s], gap to the leader [m], offset from the lane centre [m]
        at steps ``1 .. T``.
    v_l : Tensor of shape (W, T)
        The leader's speed [m/s] at steps ``1 .. T`` (replayed).
    alive : Tensor of bool, shape (W, T)
        The follower had not hit its leader before the step.
    in_line : Tensor of bool, shape (W, T)
        Follower and leader overlap laterally (the gap is a gap; a follower
        that drifted into the next lane may pass its leader).
    crash : Tensor of bool, shape (W,)
    """

    v: Tensor
    v_l: Tensor
    gap: Tensor
    offset: Tensor
    alive: Tensor
    in_line: Tensor
    crash: Tensor


def differentiable_replay(
    windows: CarFollowingWindows,
    net: DriverNet,
    road: Road,
    seeds: Tensor,
    guard: BrakeGuard | None = None,
) -> ClosedLoopTrace:
    """Replay ``windows`` with the network driving, keeping the graph.

    Parameters
    ----------
    windows : CarFollowingWindows
        ``W`` windows of ``T`` steps.
    net : DriverNet
        Its shared head drives (gradient to every weight).
    road : Road
    seeds : Tensor of int64, shape (W,)
        Per-window noise seeds.
    guard : BrakeGuard, optional
        The follower's emergency brake (None: the network alone).

    Returns
    -------
    ClosedLoopTrace
    """
    sim, state, replay_leader = replay_setup(windows, road)
    both = torch.ones(2, dtype=torch.bool)
    driver = LearnedDriver(net, controlled=both, stochastic=True, guard=guard)
    actor = replay_leader(driver)
    actors = [actor]
    masks = sim.controlled(actors, state.n_vehicles)
    xi = pack_xi(net.last.weight, net.last.bias).expand(len(windows), -1)
    carry, _ = sim.start(state, actors, seeds, [xi])
    centre = torch.as_tensor(road.lane_center_y(windows.lane))
    half_lengths = torch.as_tensor(0.5 * (windows.len_f + windows.len_l))
    half_widths = torch.as_tensor(0.5 * windows.width_f + 0.5 * DEFAULT_WIDTH)
    v, v_l, gap, offset, alive, in_line = [], [], [], [], [], []
    for t in range(windows.n_steps):
        alive.append(carry.alive)
        carry, _ = sim.step(carry, t, seeds, actors, masks)
        s = carry.state
        v.append(s.speed[:, 0])
        v_l.append(s.speed[:, 1])
        gap.append(s.x[:, 1] - s.x[:, 0] - half_lengths.to(s.x))
        offset.append(s.y[:, 0] - centre.to(s.y))
        in_line.append((s.y[:, 1] - s.y[:, 0]).abs() < half_widths.to(s.y))
    return ClosedLoopTrace(
        v=torch.stack(v, 1),
        v_l=torch.stack(v_l, 1),
        gap=torch.stack(gap, 1),
        offset=torch.stack(offset, 1),
        alive=torch.stack(alive, 1),
        in_line=torch.stack(in_line, 1),
        crash=carry.crash,
    )


def simulated_transitions(
    trace: ClosedLoopTrace, windows: CarFollowingWindows
) -> tuple[Tensor, Tensor]:
    """MGAIL's discriminator inputs of the simulated follower, with gradient.

    Parameters
    ----------
    trace : ClosedLoopTrace
        Of ``windows`` (``T`` steps).
    windows : CarFollowingWindows
        Give the initial state (step 0).

    Returns
    -------
    x : Tensor of shape (W, T - 1, 5)
        :func:`~avrisk.learning.imitation.discriminator.transition_features` of steps
        ``1 .. T-1``.
    valid : Tensor of bool, shape (W, T - 1)
        The step was simulated (its first state had not crashed).
    """

    def track(first: np.ndarray, rest: Tensor) -> Tensor:
        return torch.cat([torch.as_tensor(first, dtype=rest.dtype)[:, None], rest], 1)

    x = transition_features(
        track(windows.v_f[:, 0], trace.v),
        track(windows.v_l[:, 0], trace.v_l),
        track(windows.gap[:, 0], trace.gap),
    )
    return x[:, 1:], trace.alive[:, 1:]


def closed_loop_loss(
    trace: ClosedLoopTrace,
    windows: CarFollowingWindows,
    config: ClosedLoopConfig,
    discriminator: Discriminator | None = None,
) -> tuple[Tensor, dict[str, float]]:
    """Imitation of the recorded follower, the barriers, and MGAIL's reward.

    Parameters
    ----------
    trace : ClosedLoopTrace
        Of ``windows``.
    windows : CarFollowingWindows
    config : ClosedLoopConfig
        The terms' weights; ``ttc_margin = 0`` leaves out the TTC barrier.
    discriminator : Discriminator, optional
        With it (and ``config.adversarial_weight``), the loss gets minus the
        weighted mean discriminator reward of the simulated transitions.

    Returns
    -------
    loss : Tensor of shape ()
        Mean over the windows' alive steps.
    parts : dict of str to float
        The imitation terms ``"speed"``, ``"gap"``, ``"offset"``, the
        barriers ``"safety"`` (gap) and ``"ttc"`` (0 when off),
        ``"crash_rate"``, and ``"reward"`` (mean discriminator reward; with a
        discriminator only).
    """
    dtype = trace.v.dtype
    alive = trace.alive.to(dtype)
    n = alive.sum().clamp_min(1.0)
    huber = torch.nn.functional.huber_loss

    def imitate(sim: Tensor, human: np.ndarray, scale: float, rows: Tensor) -> Tensor:
        target = torch.as_tensor(human[:, 1:], dtype=dtype)
        err = huber(sim / scale, target / scale, reduction="none")
        return (err * alive * rows[:, None]).sum() / n

    every = torch.ones(len(windows), dtype=dtype)
    lateral = torch.as_tensor(windows.has_lateral, dtype=dtype)
    speed = imitate(trace.v, windows.v_f, SPEED_SCALE, every)
    gap = imitate(trace.gap, windows.gap, GAP_SCALE, every)
    offset = imitate(trace.offset, windows.offset, OFFSET_SCALE, lateral)
    imitation = config.imitation_weight * (speed + gap) + config.offset_weight * offset
    in_line = alive * trace.in_line.to(dtype)
    safety = (torch.relu(config.gap_margin - trace.gap) ** 2 * in_line).sum() / n
    ttc = torch.zeros((), dtype=dtype)
    if config.ttc_margin > 0:
        closing = trace.v - trace.v_l
        excess = torch.relu(closing - trace.gap / config.ttc_margin)
        ttc = (excess**2 * in_line).sum() / n
    loss = imitation + config.safety_weight * safety + config.ttc_weight * ttc
    parts = {
        "speed": float(speed.detach()),
        "gap": float(gap.detach()),
        "offset": float(offset.detach()),
        "safety": float(safety.detach()),
        "ttc": float(ttc.detach()),
        "crash_rate": float(trace.crash.to(dtype).mean()),
    }
    if discriminator is not None:
        x, valid = simulated_transitions(trace, windows)
        valid = valid.to(dtype)
        reward = (discriminator.reward(x) * valid).sum() / valid.sum().clamp_min(1.0)
        loss = loss - config.adversarial_weight * reward
        parts["reward"] = float(reward.detach())
    return loss, parts


def split_windows(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Training and validation indices of ``n`` windows, sorted.

    :func:`closed_loop_finetune` keeps ``round(fraction n)`` (at least one)
    windows, drawn with ``seed``, for early stopping.

    Returns
    -------
    train, val : ndarray of int64
    """
    order = np.random.default_rng(seed).permutation(n)
    n_val = max(1, int(round(fraction * n)))
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def stressed(windows: CarFollowingWindows, factor: float) -> CarFollowingWindows:
    """``windows`` whose leaders change speed ``factor`` times as fast.

    The leader's speed becomes ``max(v0 + factor (v_l(t) - v0), 0)``, ``v0``
    its first speed: a leader that brakes brakes ``factor`` times as hard
    and stops sooner. The follower's record no longer belongs to that
    leader, so such windows are for the barriers only.

    Parameters
    ----------
    windows : CarFollowingWindows
        ``W`` windows of ``T`` steps.
    factor : float
        At least 1 (:class:`ClosedLoopConfig` checks it).

    Returns
    -------
    CarFollowingWindows
        The same windows with ``v_l`` of shape (W, T+1) [m/s] replaced.
    """
    v0 = windows.v_l[:, :1]
    v_l = np.maximum(v0 + factor * (windows.v_l - v0), 0.0)
    return dataclasses.replace(windows, v_l=v_l)


def _minibatch_seeds(seed: int, it: int, n: int, config: ClosedLoopConfig) -> Tensor:
    """Noise seeds of step ``it``'s ``n`` minibatch replays, int64 of shape (n,)."""
    return torch.as_tensor(
        seed * 1_000_003 + it * config.batch_windows + np.arange(n),
        dtype=torch.int64,
    )


def _discriminator_step(
    disc: Discriminator | None,
    trace: ClosedLoopTrace,
    windows: CarFollowingWindows,
    config: ClosedLoopConfig,
) -> dict[str, float]:
    """Update ``disc`` on a minibatch's simulated transitions; its accuracy.

    Returns ``{"disc_accuracy": ...}``, or ``{}`` without a discriminator.
    """
    if disc is None:
        return {}
    x, valid = simulated_transitions(trace, windows)
    return {
        "disc_accuracy": disc.update(x[valid], config.disc_epochs, config.disc_batch)
    }


def _stress_seeds(
    minibatch_seeds: Tensor, seed: int, it: int, n: int, config: ClosedLoopConfig
) -> Tensor:
    """Noise seeds of step ``it``'s ``n`` stress replays, int64 of shape (n,).

    With ``stress_own_noise`` they follow every minibatch seed of the run;
    without it they are those of minibatch windows 7, 8, ... (the stress
    replays then share those windows' noise streams), as when the shipped
    files were trained.
    """
    if not config.stress_own_noise:
        return minibatch_seeds[0] + 7 + torch.arange(n)
    first = seed * 1_000_003 + config.iterations * config.batch_windows
    return torch.as_tensor(
        first + it * config.stress_windows + np.arange(n), dtype=torch.int64
    )


def _hard_braking(windows: CarFollowingWindows, config: ClosedLoopConfig) -> np.ndarray:
    """Whether each window's leader brakes harder than ``hard_brake_decel``."""
    leader_decel = np.diff(windows.v_l, axis=1).min(axis=1) / DT
    return leader_decel < config.hard_brake_decel


def _minibatch_weights(
    windows: CarFollowingWindows, config: ClosedLoopConfig
) -> np.ndarray | None:
    """Draw probabilities of ``windows``: hard-braking ones oversampled, bands weighed.

    None (uniform draws, as ``rng.choice`` without ``p``) when
    ``hard_brake_oversample`` is 1 and ``congested_share`` None. A band
    without windows keeps its share at 0.
    """
    if config.hard_brake_oversample == 1.0 and config.congested_share is None:
        return None
    hard = _hard_braking(windows, config)
    weight = np.where(hard, config.hard_brake_oversample, 1.0)
    if config.congested_share is not None:
        congested = window_bands(windows) == BANDS[0]
        for band, share in (
            (congested, config.congested_share),
            (~congested, 1.0 - config.congested_share),
        ):
            if band.any():
                weight[band] *= share / weight[band].sum()
    return weight / weight.sum()


def closed_loop_finetune(
    net: DriverNet,
    windows: CarFollowingWindows,
    config: ClosedLoopConfig,
    seed: int,
    progress: Progress | None = None,
    *,
    guard: BrakeGuard | None = None,
) -> list[dict[str, float]]:
    """Train ``net`` in place on closed-loop replays of training windows.

    Parameters
    ----------
    net : DriverNet
        Trained by behaviour cloning (and DAgger); its noise buffers set.
    windows : CarFollowingWindows
        *Training* windows; a ``validation_fraction`` of them (by ``seed``)
        is kept for early stopping.
    config : ClosedLoopConfig
    seed : int
        Minibatches and the actions' noise.
    progress : callable, optional
        Receives ``TrainEvent("closed_loop", ...)`` after every step.
    guard : BrakeGuard, optional
        The minibatch and validation replays drive with this emergency brake
        on top of the network (``ClosedLoopConfig.drive_with_guard``); the
        stress replays never do, so that the network itself learns to stop in
        their emergencies. None: the network alone everywhere.

    Returns
    -------
    list of dict
        Per validation: ``iteration``, the training minibatch's loss and its
        parts, ``val_loss`` and the validation windows' parts (``val_``...).
        The kept weights are those of the lowest ``val_loss`` (iteration 0:
        the network as given).
    """
    if config.iterations == 0 or len(windows) < 2:
        return []
    road = Road()
    train_idx, val_idx = split_windows(len(windows), config.validation_fraction, seed)
    train_windows, val = windows.take(train_idx), windows.take(val_idx)
    val_seeds = torch.arange(len(val), dtype=torch.int64) + 1_000_003 * (seed + 1)
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    disc = None
    if config.adversarial_weight > 0:
        disc = Discriminator(train_windows, config.disc_hidden, config.disc_lr, seed)

    def validate() -> dict[str, float]:
        with torch.no_grad():
            trace = differentiable_replay(val, net, road, val_seeds, guard)
            loss, parts = closed_loop_loss(trace, val, config)
        return {"val_loss": float(loss)} | {f"val_{k}": v for k, v in parts.items()}

    first = validate()
    best_loss = first["val_loss"]
    best = copy.deepcopy(net.state_dict())
    history: list[dict[str, float]] = [{"iteration": 0.0, **first}]
    net.train()
    draw = _minibatch_weights(train_windows, config)
    hard_idx = train_idx[_hard_braking(train_windows, config)]
    barriers_only = dataclasses.replace(config, imitation_weight=0.0, offset_weight=0.0)
    for it in range(config.iterations):
        size = min(config.batch_windows, len(train_idx))
        batch = rng.choice(train_idx, size=size, p=draw)
        seeds = _minibatch_seeds(seed, it, len(batch), config)
        part = windows.take(batch)
        trace = differentiable_replay(part, net, road, seeds, guard)
        disc_row = _discriminator_step(disc, trace, part, config)
        loss, parts = closed_loop_loss(trace, part, config, disc)
        if config.stress_windows > 0 and len(hard_idx) > 0:
            pick = rng.choice(hard_idx, size=config.stress_windows)
            harder = stressed(windows.take(pick), config.stress_factor)
            stress_seeds = _stress_seeds(seeds, seed, it, len(pick), config)
            trace = differentiable_replay(harder, net, road, stress_seeds)
            stress, stress_parts = closed_loop_loss(trace, harder, barriers_only)
            loss = loss + stress
            parts["stress_crash_rate"] = stress_parts["crash_rate"]
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), config.grad_clip)
        opt.step()
        row = {"iteration": float(it + 1), "loss": float(loss.detach()), **parts}
        row |= disc_row
        if (it + 1) % config.validate_every == 0 or it + 1 == config.iterations:
            row |= validate()
            history.append(row)
            if row["val_loss"] < best_loss:
                best_loss = row["val_loss"]
                best = copy.deepcopy(net.state_dict())
        if progress is not None:
            progress(TrainEvent("closed_loop", it + 1, config.iterations, row))
    net.load_state_dict(best)
    return history
