"""GAIL with PPO of human car following, after BC + DAgger: a tried idea, not shipped.

``benchmarks/gail_realism.py`` fine-tunes the shipped network with
:func:`gail_finetune` and scores it as ``avrisk realism`` does
(docs/benchmarks-history.md, "GAIL fine-tuning of the acceleration head (not
shipped)"); it did not reduce the rear-end collisions, so ``avrisk
train-drivers`` does not run it and the method lives here, beside that
benchmark, rather than in the package.

GAIL (Ho and Ermon 2016) trains a discriminator ``D`` to tell human
transitions from the policy's and rewards the policy for transitions that
``D`` takes for human; the policy is improved by a policy-gradient method,
here PPO (Schulman et al. 2017). Everything runs in our batched simulator::

    for every iteration:
        replay a random subset of *training* car-following windows with the
            current network driving the follower (the leader replays the
            human record: :func:`avrisk.learning.replay.replay`)
        update D on policy transitions vs human transitions of all training
            windows (logistic loss)
        reward r_t = -log(1 - D(x_t)) = softplus(logit D(x_t)), minus
            ``collision_penalty`` on the step that hits the leader
        advantages by GAE with a separate value network; PPO clipped
            surrogate on the acceleration head

The discriminator, its inputs and its training are the package's
(:mod:`avrisk.learning.imitation.discriminator`), which model-based GAIL
(:mod:`avrisk.learning.imitation.mgail`) shares.

Policy and what is tuned
------------------------
The policy is the deployed sampler of
:class:`~avrisk.agents.drivers.driver.LearnedDriver`: ``a_t = m_t + sigma_t
eps_t`` with AR(1) noise ``eps_t = rho eps_{t-1} + sqrt(1 - rho^2) z_t``, so
its log-density given the past is Gaussian in the innovation
(:func:`accel_log_prob`). Only the acceleration rows (mean and
log-variance) of the shared head ``net.last`` are tuned (202 numbers): the
reward says nothing about steering, which stays exactly as behaviour cloning
and DAgger left it, and the trunk stays shared with the bootstrap heads of
the ``xi`` prior; the change of the head is carried over to the prior by a
translation (:func:`translate_prior`). The noise buffers
(``noise_correlation``, ``noise_scale``) are kept.

This is model-free GAIL with PPO, on car following only (no lane changes, no
multi-vehicle traffic).

Why one module: it is one method, kept whole beside the benchmark that runs
it, and the package does not ship it.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from avrisk.agents.drivers.driver import LearnedDriver, LearnedState
from avrisk.agents.drivers.features import features_from_observation
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import XiPrior
from avrisk.learning.imitation.discriminator import (
    human_transitions,
    mlp,
    train_discriminator,
    transition_features,
)
from avrisk.learning.replay import CarFollowingWindows, replay
from avrisk.learning.train_config import Progress, TrainEvent
from avrisk.sim import Road
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = [
    "ACCEL_ROWS",
    "GailConfig",
    "PPOBatch",
    "accel_log_prob",
    "gae",
    "gail_finetune",
    "ppo_update",
    "translate_prior",
]

#: Rows of the head (``net.last``) that GAIL tunes: accel mean and log-variance.
ACCEL_ROWS = (0, 2)


@dataclass(frozen=True)
class GailConfig:
    """Settings of :func:`gail_finetune` (defaults: a few minutes on one core).

    Parameters
    ----------
    iterations : int, default=40
        Rollout / discriminator / PPO rounds.
    windows_per_iter : int, default=512
        Training windows replayed per round (fewer if there are fewer).
    disc_hidden : int, default=64
        Width of the discriminator's two hidden layers.
    disc_epochs : int, default=2
        Passes over the round's transitions per discriminator update.
    disc_lr : float, default=1e-3
        Adam learning rate of the discriminator.
    disc_batch : int, default=4096
        Transitions of each class per discriminator step.
    collision_penalty : float, default=10.0
        Subtracted from the reward of the step that hits the leader [-]
        (about 15 steps of the reward at ``D = 1/2``). Humans never collide in
        the data, but a discriminator on a few features cannot be relied on
        to see what precedes a collision; the penalty is a prior, not data.
    gamma : float, default=0.99
        Discount per step (0.1 s).
    gae_lambda : float, default=0.95
    ppo_epochs : int, default=4
        Passes over the round's windows per PPO update.
    ppo_windows : int, default=128
        Windows per PPO minibatch (whole windows: the AR(1) log-density of a
        step needs the previous one).
    policy_lr : float, default=3e-4
        Adam learning rate of the tuned head rows.
    clip : float, default=0.2
        PPO ratio clip ``epsilon``.
    entropy_coef : float, default=0.0
        Weight of the policy entropy bonus.
    max_grad_norm : float, default=0.5
    value_hidden : int, default=64
        Width of the value network's two hidden layers.
    value_lr : float, default=1e-3
    """

    iterations: int = 40
    windows_per_iter: int = 512
    disc_hidden: int = 64
    disc_epochs: int = 2
    disc_lr: float = 1e-3
    disc_batch: int = 4096
    collision_penalty: float = 10.0
    gamma: float = 0.99
    gae_lambda: float = 0.95
    ppo_epochs: int = 4
    ppo_windows: int = 128
    policy_lr: float = 3e-4
    clip: float = 0.2
    entropy_coef: float = 0.0
    max_grad_norm: float = 0.5
    value_hidden: int = 64
    value_lr: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("iterations", "windows_per_iter", "ppo_windows", "disc_batch"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")


class _Recorder:
    """An actor that drives with a learned driver and records vehicle 0."""

    def __init__(self, driver: LearnedDriver) -> None:
        self.driver = driver
        self.controlled = driver.controlled
        self.noise = driver.noise
        self.features: list[Tensor] = []
        self.eps: list[Tensor] = []

    def init(self, obs: Observation, params: Tensor | None) -> LearnedState:
        return self.driver.init(obs, params)

    def act(
        self, obs: Observation, state: LearnedState, noise: Tensor | None
    ) -> tuple[Action, LearnedState]:
        action, state = self.driver.act(obs, state, noise)
        assert state.eps is not None  # the driver samples
        self.features.append(features_from_observation(obs)[:, 0].float())
        self.eps.append(state.eps[:, 0, 0].float())
        return action, state


@dataclass(frozen=True)
class _Rollouts:
    hidden: Tensor  # [W, T, 100] trunk output of the follower
    accel: Tensor  # [W, T] sampled acceleration (before the no-reverse clip)
    x: Tensor  # [W, T, 5] discriminator inputs
    state: Tensor  # [W, T, 4] value-network inputs
    valid: Tensor  # [W, T] step simulated (and t >= 1 for ``disc``)
    last: Tensor  # [W] index of the last simulated step
    crash: Tensor  # [W] bool


def _rollouts(
    net: DriverNet, windows: CarFollowingWindows, road: Road, seed: int
) -> _Rollouts:
    rec = _Recorder(LearnedDriver(net, controlled=torch.ones(2, dtype=torch.bool)))
    res = replay(windows, rec, road, seed=seed)
    n, t = len(windows), windows.n_steps
    feats = torch.zeros(n, t, rec.features[0].shape[-1])
    eps = torch.zeros(n, t)
    feats[:, : len(rec.features)] = torch.stack(rec.features, 1)
    eps[:, : len(rec.eps)] = torch.stack(rec.eps, 1)
    with torch.no_grad():
        hidden = net.trunk(feats)
        mean, std = _accel_gaussian(net, hidden)
    valid = torch.from_numpy(res.alive[:, 1:].copy())
    tracks = (torch.as_tensor(a) for a in (res.v, res.v_l, res.gap))
    x = transition_features(*tracks).float()
    time = torch.arange(t, dtype=torch.float32).expand(n, t) / t
    return _Rollouts(
        hidden=hidden,
        accel=mean + std * eps,
        x=x,
        state=torch.cat([x[..., :3], time[..., None]], -1),
        valid=valid,
        last=valid.sum(1) - 1,
        crash=torch.from_numpy(res.crash.copy()),
    )


# ----------------------------------------------------------------- policy
def _accel_gaussian(net: DriverNet, hidden: Tensor) -> tuple[Tensor, Tensor]:
    """Mean [m/s^2] and sampling standard deviation [m/s^2] of the acceleration."""
    dist = net.distribution(net.head(hidden))
    std = net.noise_scale[0] * torch.exp(0.5 * dist.accel_log_var)
    return dist.accel_mean, std


def accel_log_prob(
    net: DriverNet, hidden: Tensor, accel: Tensor
) -> tuple[Tensor, Tensor]:
    """Log-density of sampled accelerations under the AR(1) sampler, per step.

    With ``eps_t = (a_t - m_t) / sigma_t`` and ``rho = net.noise_correlation[0]``,
    ``log p(a_t | past) = log N(eps_t; rho eps_{t-1}, 1 - rho^2) - log sigma_t``
    (``eps_{-1} = 0`` and unit variance at ``t = 0``, as
    :func:`~avrisk.agents.drivers.sampling.ar1_noise` starts).

    Parameters
    ----------
    net : DriverNet
        ``sigma_t = noise_scale[0] * exp(accel_log_var / 2)``.
    hidden : Tensor of shape (W, T, 100)
        Trunk outputs.
    accel : Tensor of shape (W, T)
        Sampled accelerations [m/s^2].

    Returns
    -------
    log_p : Tensor of shape (W, T)
        [log 1/(m/s^2)].
    entropy : Tensor of shape (W, T)
        Entropy of the step's conditional Gaussian [nats].
    """
    mean, std = _accel_gaussian(net, hidden)
    rho = float(net.noise_correlation[0])
    eps = (accel - mean) / std
    prev = F.pad(eps[:, :-1], (1, 0))
    var = torch.full_like(eps, 1.0 - rho * rho)
    var[:, 0] = 1.0
    log_std = torch.log(std) + 0.5 * torch.log(var)
    log_p = -0.5 * (eps - rho * prev) ** 2 / var - log_std - 0.5 * math.log(2 * math.pi)
    entropy = log_std + 0.5 * math.log(2 * math.pi * math.e)
    return log_p, entropy


def gae(
    rewards: Tensor, values: Tensor, last: Tensor, gamma: float, lam: float
) -> Tensor:
    """Generalised advantage estimates; an episode ends after step ``last``.

    Parameters
    ----------
    rewards, values : Tensor of shape (W, T)
    last : Tensor of int, shape (W,)
        Last step of each episode (its successor's value counts as 0).
    gamma, lam : float

    Returns
    -------
    Tensor of shape (W, T)
        0 after ``last``.
    """
    n, t = rewards.shape
    steps = torch.arange(t).expand(n, t)
    live = (steps <= last[:, None]).float()
    nonterminal = (steps < last[:, None]).float()
    next_v = F.pad(values[:, 1:], (0, 1)) * nonterminal
    delta = (rewards + gamma * next_v - values) * live
    adv = torch.zeros_like(rewards)
    running = torch.zeros(n)
    for k in range(t - 1, -1, -1):
        running = delta[:, k] + gamma * lam * nonterminal[:, k] * running
        adv[:, k] = running
    return adv


@dataclass(frozen=True)
class PPOBatch:
    """One round of experience for :func:`ppo_update`, per window and step.

    Attributes
    ----------
    hidden : Tensor of shape (W, T, 100)
    accel : Tensor of shape (W, T)
        Sampled accelerations [m/s^2].
    old_log_p : Tensor of shape (W, T)
    advantages, returns : Tensor of shape (W, T)
    state : Tensor of shape (W, T, S)
        Value-network inputs (standardised).
    valid : Tensor of bool, shape (W, T)
    """

    hidden: Tensor
    accel: Tensor
    old_log_p: Tensor
    advantages: Tensor
    returns: Tensor
    state: Tensor
    valid: Tensor


def _head_optimizer(net: DriverNet, lr: float) -> torch.optim.Adam:
    for p in net.parameters():
        p.requires_grad_(False)
    net.last.weight.requires_grad_(True)
    net.last.bias.requires_grad_(True)
    return torch.optim.Adam([net.last.weight, net.last.bias], lr=lr)


def _mask_head_grad(net: DriverNet) -> None:
    """Zero the gradient of the steering rows: only ACCEL_ROWS move."""
    keep = torch.zeros(net.last.bias.shape[0], dtype=torch.bool)
    keep[list(ACCEL_ROWS)] = True
    net.last.weight.grad[~keep] = 0.0
    net.last.bias.grad[~keep] = 0.0


def ppo_update(
    net: DriverNet,
    value_net: nn.Module,
    batch: PPOBatch,
    policy_opt: torch.optim.Optimizer,
    value_opt: torch.optim.Optimizer,
    config: GailConfig,
    generator: torch.Generator,
) -> dict[str, float]:
    """PPO epochs on whole-window minibatches: clipped surrogate + value MSE.

    Parameters
    ----------
    net : DriverNet
        Its head's ACCEL_ROWS are updated by ``policy_opt``.
    value_net : nn.Module
        ``state -> value``, updated by ``value_opt``.
    batch : PPOBatch
    policy_opt, value_opt : torch.optim.Optimizer
    config : GailConfig
        ``ppo_epochs``, ``ppo_windows``, ``clip``, ``entropy_coef``,
        ``max_grad_norm``.
    generator : torch.Generator
        Shuffles the windows.

    Returns
    -------
    dict of str to float
        Last minibatch's ``"clip_fraction"`` and ``"approx_kl"``, and
        ``"value_loss"``.
    """
    valid = batch.valid
    adv = batch.advantages
    adv = (adv - adv[valid].mean()) / adv[valid].std().clamp_min(1e-8)
    n = batch.hidden.shape[0]
    out: dict[str, float] = {}
    for _ in range(config.ppo_epochs):
        perm = torch.randperm(n, generator=generator)
        for s in range(0, n, config.ppo_windows):
            idx = perm[s : s + config.ppo_windows]
            m = valid[idx]
            log_p, entropy = accel_log_prob(net, batch.hidden[idx], batch.accel[idx])
            ratio = torch.exp(log_p - batch.old_log_p[idx])[m]
            a = adv[idx][m]
            surrogate = torch.minimum(
                ratio * a, torch.clamp(ratio, 1 - config.clip, 1 + config.clip) * a
            )
            loss = -surrogate.mean() - config.entropy_coef * entropy[m].mean()
            policy_opt.zero_grad(set_to_none=True)
            loss.backward()
            _mask_head_grad(net)
            nn.utils.clip_grad_norm_(
                [net.last.weight, net.last.bias], config.max_grad_norm
            )
            policy_opt.step()
            value = value_net(batch.state[idx]).squeeze(-1)
            value_loss = ((value - batch.returns[idx]) ** 2)[m].mean()
            value_opt.zero_grad(set_to_none=True)
            value_loss.backward()
            value_opt.step()
            with torch.no_grad():
                out = {
                    "clip_fraction": float(
                        ((ratio - 1).abs() > config.clip).float().mean()
                    ),
                    "approx_kl": float((batch.old_log_p[idx][m] - log_p[m]).mean()),
                    "value_loss": float(value_loss),
                }
    return out


# -------------------------------------------------------------- top level
@dataclass(frozen=True)
class _Learners:
    """The discriminator and value network of a run, their optimisers, the policy's.

    ``human`` holds the human transitions standardised by their own mean
    ``x_mean`` and scale ``x_scale``; the value network's inputs are
    standardised by ``s_mean`` and ``s_scale``.
    """

    disc: nn.Module
    value_net: nn.Module
    disc_opt: torch.optim.Optimizer
    value_opt: torch.optim.Optimizer
    policy_opt: torch.optim.Optimizer
    human: Tensor
    x_mean: Tensor
    x_scale: Tensor
    s_mean: Tensor
    s_scale: Tensor


def _learners(
    net: DriverNet, windows: CarFollowingWindows, config: GailConfig, seed: int
) -> _Learners:
    """The discriminator and value network, initialised from ``seed``."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        disc = mlp(5, config.disc_hidden)
        value_net = mlp(4, config.value_hidden)
    human = human_transitions(windows)
    x_mean, x_scale = human.mean(0), human.std(0).clamp_min(1e-6)
    return _Learners(
        disc=disc,
        value_net=value_net,
        disc_opt=torch.optim.Adam(disc.parameters(), lr=config.disc_lr),
        value_opt=torch.optim.Adam(value_net.parameters(), lr=config.value_lr),
        policy_opt=_head_optimizer(net, config.policy_lr),
        human=(human - x_mean) / x_scale,
        x_mean=x_mean,
        x_scale=x_scale,
        s_mean=torch.cat([x_mean[:3], torch.tensor([0.5])]),
        s_scale=torch.cat([x_scale[:3], torch.tensor([0.3])]),
    )


def _gail_round(
    net: DriverNet,
    ro: _Rollouts,
    learners: _Learners,
    config: GailConfig,
    generator: torch.Generator,
) -> dict[str, float]:
    """One round on replayed rollouts: discriminator, rewards, GAE, PPO.

    Returns the round's history row without its ``"iteration"`` (see
    :func:`gail_finetune`).
    """
    x = (ro.x - learners.x_mean) / learners.x_scale
    scored = ro.valid.clone()
    scored[:, 0] = False
    acc = train_discriminator(
        learners.disc,
        learners.human,
        x[scored],
        learners.disc_opt,
        epochs=config.disc_epochs,
        batch=config.disc_batch,
        generator=generator,
    )
    state = (ro.state - learners.s_mean) / learners.s_scale
    with torch.no_grad():
        gail_r = F.softplus(learners.disc(x).squeeze(-1)) * scored
        rewards = gail_r.clone()
        hit = torch.nonzero(ro.crash).squeeze(-1)
        rewards[hit, ro.last[hit]] -= config.collision_penalty
        values = learners.value_net(state).squeeze(-1)
        adv = gae(rewards, values, ro.last, config.gamma, config.gae_lambda)
        old_log_p, entropy = accel_log_prob(net, ro.hidden, ro.accel)
    batch = PPOBatch(
        hidden=ro.hidden,
        accel=ro.accel,
        old_log_p=old_log_p,
        advantages=adv,
        returns=adv + values,
        state=state,
        valid=ro.valid,
    )
    stats = ppo_update(
        net,
        learners.value_net,
        batch,
        learners.policy_opt,
        learners.value_opt,
        config,
        generator,
    )
    return {
        "disc_accuracy": acc,
        "mean_reward": float(gail_r[scored].mean()),
        "entropy": float(entropy[ro.valid].mean()),
        "collision_rate": float(ro.crash.float().mean()),
        **stats,
    }


def gail_finetune(
    net: DriverNet,
    windows: CarFollowingWindows,
    config: GailConfig = GailConfig(),
    seed: int = 0,
    *,
    road: Road | None = None,
    progress: Progress | None = None,
) -> tuple[DriverNet, list[dict[str, float]]]:
    """Fine-tune the acceleration head of a driver network by GAIL with PPO.

    Parameters
    ----------
    net : DriverNet
        Starting point (e.g. the shipped behaviour-cloned network); not
        modified. Its ``noise_scale[0]`` must be positive (PPO needs a
        stochastic policy).
    windows : CarFollowingWindows
        *Training* windows: the human transitions and the replayed episodes
        (never evaluation windows).
    config : GailConfig
    seed : int, default=0
        Seeds the window draws, the networks' initialisation, the
        minibatches and the action noise. One torch thread gives
        bit-identical results for a seed on a machine.
    road : Road, optional
        Default ``Road()``.
    progress : callable, optional
        Receives ``TrainEvent("gail", k, iterations, row)`` after every round.

    Returns
    -------
    net : DriverNet
        A tuned copy, in eval mode.
    history : list of dict
        Per round: ``"iteration"``, ``"disc_accuracy"``, ``"mean_reward"`` (GAIL
        reward per step, penalty excluded), ``"entropy"`` [nats per step],
        ``"collision_rate"`` (fraction of replayed windows), and PPO's
        ``"clip_fraction"``, ``"approx_kl"``, ``"value_loss"``.

    Raises
    ------
    ValueError
        If the network does not sample its accelerations.
    """
    if float(net.noise_scale[0]) <= 0:
        raise ValueError("GAIL needs a stochastic policy: net.noise_scale[0] > 0")
    road = Road() if road is None else road
    net = copy.deepcopy(net).eval()
    rng = np.random.default_rng(seed)
    gen = torch.Generator().manual_seed(seed)
    learners = _learners(net, windows, config, seed)
    k = min(config.windows_per_iter, len(windows))
    history = []
    for it in range(config.iterations):
        pick = np.sort(rng.choice(len(windows), size=k, replace=False))
        ro = _rollouts(net, windows.take(pick), road, seed * 1000 + it)
        row = {
            "iteration": float(it + 1),
            **_gail_round(net, ro, learners, config, gen),
        }
        history.append(row)
        if progress is not None:
            progress(TrainEvent("gail", it + 1, config.iterations, row))
    for p in net.parameters():
        p.requires_grad_(True)
    return net.eval(), history


def translate_prior(prior: XiPrior, before: DriverNet, after: DriverNet) -> XiPrior:
    """Carry a change of the shared head over to the ``xi`` prior.

    ``mu0`` and every member move by ``after.default_xi - before.default_xi``;
    the precision (the spread of the bootstrap heads) is kept.

    Parameters
    ----------
    prior : XiPrior
        Fitted for ``before``.
    before, after : DriverNet
        Same trunk; ``after``'s head tuned (:func:`gail_finetune`).

    Returns
    -------
    XiPrior
    """
    shift = (after.default_xi - before.default_xi).double().numpy()
    return XiPrior(
        mean=prior.mean + shift,
        precision=prior.precision,
        members=prior.members + shift,
        meta={**prior.meta, "translated_by": "gail_finetune"},
    )
