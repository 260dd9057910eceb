"""Adversarial imitation (GAIL with PPO) of human car following, after BC + DAgger.

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

Discriminator input (compact, documented, computed identically from the
human record and the simulated trace): ``x_t = (v_t [m/s], gap_t [m],
v_leader,t - v_t [m/s], a_{t-1} [m/s^2], a_t [m/s^2])`` with the *realised*
accelerations ``a_t = (v_{t+1} - v_t) / dt``; ``a_{t-1}`` makes jerk visible.
It is defined for ``t >= 1``; the first step gets reward 0. Inputs are
standardised by the human statistics.

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
multi-vehicle traffic). Model-based GAIL (the paper's MGAIL, Baram et al.
2017), whose policy gradient is the discriminator's reward differentiated
through the dynamics, reuses :func:`transition_features` and
:func:`train_discriminator` in :mod:`avrisk.learning.imitation.mgail` and
:mod:`avrisk.learning.training.closed_loop`, through the simulator's own step.
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
from avrisk.learning.replay import DT, CarFollowingWindows, replay
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
    "human_transitions",
    "mlp",
    "ppo_update",
    "train_discriminator",
    "transition_features",
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


def mlp(n_in: int, hidden: int, n_out: int = 1) -> nn.Sequential:
    """Two tanh hidden layers of ``hidden`` units (discriminator, value)."""
    return nn.Sequential(
        nn.Linear(n_in, hidden),
        nn.Tanh(),
        nn.Linear(hidden, hidden),
        nn.Tanh(),
        nn.Linear(hidden, n_out),
    )


# ------------------------------------------------------------ transitions
def transition_features(v: Tensor, v_l: Tensor, gap: Tensor) -> Tensor:
    """Discriminator inputs of every step of car-following tracks.

    Differentiable: MGAIL (:mod:`avrisk.learning.imitation.mgail`) back-propagates the
    discriminator's reward through them into a simulated follower.

    Parameters
    ----------
    v, v_l : Tensor of shape (W, T+1)
        Follower and leader speed [m/s].
    gap : Tensor of shape (W, T+1)
        Bumper-to-bumper gap [m].

    Returns
    -------
    Tensor of shape (W, T, 5), the dtype of ``v``
        ``(v_t, gap_t, v_l,t - v_t, a_{t-1}, a_t)`` per step ``t``; row ``t = 0``
        has ``a_{-1} = 0`` and is not used (see the module docstring).
    """
    a = torch.diff(v, dim=1) / DT  # (W, T)
    a_prev = torch.cat([torch.zeros_like(a[:, :1]), a[:, :-1]], dim=1)
    return torch.stack([v[:, :-1], gap[:, :-1], (v_l - v)[:, :-1], a_prev, a], dim=-1)


def human_transitions(windows: CarFollowingWindows) -> Tensor:
    """Discriminator inputs of the recorded followers, steps ``t >= 1``.

    Returns
    -------
    Tensor of float32, shape (W * (T - 1), 5)
    """
    tracks = (torch.as_tensor(a) for a in (windows.v_f, windows.v_l, windows.gap))
    x = transition_features(*tracks)[:, 1:].float()
    return x.reshape(-1, x.shape[-1])


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
    :func:`~avrisk.agents.drivers.driver.ar1_noise` starts).

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


# ---------------------------------------------------------- discriminator
def train_discriminator(
    disc: nn.Module,
    human: Tensor,
    policy: Tensor,
    optimizer: torch.optim.Optimizer,
    *,
    epochs: int,
    batch: int,
    generator: torch.Generator,
) -> float:
    """Logistic regression of human (label 1) vs policy (label 0) inputs.

    Parameters
    ----------
    disc : nn.Module
        ``x -> logit D(x)`` on standardised inputs.
    human : Tensor of shape (N_h, F)
    policy : Tensor of shape (N_p, F)
    optimizer : torch.optim.Optimizer
    epochs : int
        Passes over ``policy``; every step pairs ``batch`` policy rows with
        ``batch`` human rows drawn at random.
    batch : int
    generator : torch.Generator

    Returns
    -------
    float
        Accuracy on the policy rows and as many random human rows, after the
        update [-].
    """
    n = policy.shape[0]
    for _ in range(epochs):
        perm = torch.randperm(n, generator=generator)
        for s in range(0, n, batch):
            p = policy[perm[s : s + batch]]
            h = human[
                torch.randint(0, human.shape[0], (p.shape[0],), generator=generator)
            ]
            logits = disc(torch.cat([h, p])).squeeze(-1)
            labels = torch.cat([torch.ones(len(h)), torch.zeros(len(p))])
            loss = F.binary_cross_entropy_with_logits(logits, labels)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
    h = human[torch.randint(0, human.shape[0], (n,), generator=generator)]
    with torch.no_grad():
        correct = (disc(h) > 0).sum() + (disc(policy) <= 0).sum()
    return float(correct) / (2 * n)


# -------------------------------------------------------------- top level
def _standardiser(x: Tensor) -> tuple[Tensor, Tensor]:
    return x.mean(0), x.std(0).clamp_min(1e-6)


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
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        disc = mlp(5, config.disc_hidden)
        value_net = mlp(4, config.value_hidden)
    human = human_transitions(windows)
    x_mean, x_scale = _standardiser(human)
    human = (human - x_mean) / x_scale
    s_mean = torch.cat([x_mean[:3], torch.tensor([0.5])])
    s_scale = torch.cat([x_scale[:3], torch.tensor([0.3])])
    disc_opt = torch.optim.Adam(disc.parameters(), lr=config.disc_lr)
    value_opt = torch.optim.Adam(value_net.parameters(), lr=config.value_lr)
    policy_opt = _head_optimizer(net, config.policy_lr)
    k = min(config.windows_per_iter, len(windows))
    history = []
    for it in range(config.iterations):
        pick = np.sort(rng.choice(len(windows), size=k, replace=False))
        ro = _rollouts(net, windows.take(pick), road, seed * 1000 + it)
        x = (ro.x - x_mean) / x_scale
        scored = ro.valid.clone()
        scored[:, 0] = False
        acc = train_discriminator(
            disc,
            human,
            x[scored],
            disc_opt,
            epochs=config.disc_epochs,
            batch=config.disc_batch,
            generator=gen,
        )
        state = (ro.state - s_mean) / s_scale
        with torch.no_grad():
            gail_r = F.softplus(disc(x).squeeze(-1)) * scored
            rewards = gail_r.clone()
            hit = torch.nonzero(ro.crash).squeeze(-1)
            rewards[hit, ro.last[hit]] -= config.collision_penalty
            values = value_net(state).squeeze(-1)
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
        stats = ppo_update(net, value_net, batch, policy_opt, value_opt, config, gen)
        row = {
            "iteration": float(it + 1),
            "disc_accuracy": acc,
            "mean_reward": float(gail_r[scored].mean()),
            "entropy": float(entropy[ro.valid].mean()),
            "collision_rate": float(ro.crash.float().mean()),
            **stats,
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
