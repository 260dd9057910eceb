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
    loss = imitation + safety
        imitation: Huber distance of the simulated follower's speed, gap and
            (lateral windows) lane offset to the human's, per step, each
            divided by a scale (1 m/s, 2 m, 0.3 m)
        safety: (gap_margin - gap)_+^2 per step [m^2] while the two overlap
            laterally: a barrier that grows before contact (a crash stops the
            rollout, and no gradient flows through the steps after it)
    one Adam step on every weight of the network (trunk and shared head)

Early stopping on validation windows (a fixed part of the training windows,
chosen by seed): the weights of the iteration with the lowest validation
loss are kept. The noise buffers (``noise_correlation``, ``noise_scale``)
are kept as calibrated before.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import pack_xi
from avrisk.learning.ngsim_demonstrations import DEFAULT_WIDTH
from avrisk.learning.replay import CarFollowingWindows, replay_setup
from avrisk.learning.train_config import ClosedLoopConfig, Progress, TrainEvent
from avrisk.sim import Road

__all__ = ["closed_loop_finetune", "closed_loop_loss", "differentiable_replay"]


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
    alive : Tensor of bool, shape (W, T)
        The follower had not hit its leader before the step.
    in_line : Tensor of bool, shape (W, T)
        Follower and leader overlap laterally (the gap is a gap; a follower
        that drifted into the next lane may pass its leader).
    crash : Tensor of bool, shape (W,)
    """

    v: Tensor
    gap: Tensor
    offset: Tensor
    alive: Tensor
    in_line: Tensor
    crash: Tensor


def differentiable_replay(
    windows: CarFollowingWindows, net: DriverNet, road: Road, seeds: Tensor
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

    Returns
    -------
    ClosedLoopTrace
    """
    sim, state, replay_leader = replay_setup(windows, road)
    both = torch.ones(2, dtype=torch.bool)
    actor = replay_leader(LearnedDriver(net, controlled=both, stochastic=True))
    actors = [actor]
    masks = sim.controlled(actors, state.n_vehicles)
    xi = pack_xi(net.last.weight, net.last.bias).expand(len(windows), -1)
    carry, _ = sim.start(state, actors, seeds, [xi])
    centre = torch.as_tensor(road.lane_center_y(windows.lane))
    half_lengths = torch.as_tensor(0.5 * (windows.len_f + windows.len_l))
    half_widths = torch.as_tensor(0.5 * windows.width_f + 0.5 * DEFAULT_WIDTH)
    v, gap, offset, alive, in_line = [], [], [], [], []
    for t in range(windows.n_steps):
        alive.append(carry.alive)
        carry, _ = sim.step(carry, t, seeds, actors, masks)
        s = carry.state
        v.append(s.speed[:, 0])
        gap.append(s.x[:, 1] - s.x[:, 0] - half_lengths.to(s.x))
        offset.append(s.y[:, 0] - centre.to(s.y))
        in_line.append((s.y[:, 1] - s.y[:, 0]).abs() < half_widths.to(s.y))
    return ClosedLoopTrace(
        v=torch.stack(v, 1),
        gap=torch.stack(gap, 1),
        offset=torch.stack(offset, 1),
        alive=torch.stack(alive, 1),
        in_line=torch.stack(in_line, 1),
        crash=carry.crash,
    )


def closed_loop_loss(
    trace: ClosedLoopTrace, windows: CarFollowingWindows, config: ClosedLoopConfig
) -> tuple[Tensor, dict[str, float]]:
    """Imitation of the recorded follower plus the gap barrier.

    Parameters
    ----------
    trace : ClosedLoopTrace
        Of ``windows``.
    windows : CarFollowingWindows
    config : ClosedLoopConfig

    Returns
    -------
    loss : Tensor of shape ()
        Mean over the windows' alive steps.
    parts : dict of str to float
        The imitation terms ``"speed"``, ``"gap"``, ``"offset"``, and
        ``"safety"``, ``"crash_rate"``.
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
    imitation = speed + gap + config.offset_weight * offset
    barrier = torch.relu(config.gap_margin - trace.gap) ** 2
    safety = (barrier * alive * trace.in_line.to(dtype)).sum() / n
    loss = imitation + config.safety_weight * safety
    parts = {
        "speed": float(speed.detach()),
        "gap": float(gap.detach()),
        "offset": float(offset.detach()),
        "safety": float(safety.detach()),
        "crash_rate": float(trace.crash.to(dtype).mean()),
    }
    return loss, parts


def _split(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.random.default_rng(seed).permutation(n)
    n_val = max(1, int(round(fraction * n)))
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def closed_loop_finetune(
    net: DriverNet,
    windows: CarFollowingWindows,
    config: ClosedLoopConfig,
    seed: int,
    progress: Progress | None = None,
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
    train_idx, val_idx = _split(len(windows), config.validation_fraction, seed)
    val = windows.take(val_idx)
    val_seeds = torch.arange(len(val), dtype=torch.int64) + 1_000_003 * (seed + 1)
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)

    def validate() -> dict[str, float]:
        with torch.no_grad():
            trace = differentiable_replay(val, net, road, val_seeds)
            loss, parts = closed_loop_loss(trace, val, config)
        return {"val_loss": float(loss)} | {f"val_{k}": v for k, v in parts.items()}

    first = validate()
    best_loss = first["val_loss"]
    best = copy.deepcopy(net.state_dict())
    history: list[dict[str, float]] = [{"iteration": 0.0, **first}]
    net.train()
    for it in range(config.iterations):
        batch = rng.choice(train_idx, size=min(config.batch_windows, len(train_idx)))
        seeds = torch.as_tensor(
            seed * 1_000_003 + it * config.batch_windows + np.arange(len(batch)),
            dtype=torch.int64,
        )
        part = windows.take(batch)
        trace = differentiable_replay(part, net, road, seeds)
        loss, parts = closed_loop_loss(trace, part, config)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), config.grad_clip)
        opt.step()
        row = {"iteration": float(it + 1), "loss": float(loss.detach()), **parts}
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
