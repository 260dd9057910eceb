"""A discriminator of human vs simulated car following: its inputs and training.

GAIL (Ho and Ermon 2016) and model-based GAIL (Baram et al. 2017) train a
discriminator ``D`` to tell human transitions from the policy's and reward the
policy for transitions that ``D`` takes for human. This module holds what they
share: the transition features (:func:`transition_features`), those of the
recorded followers (:func:`human_transitions`), the network (:func:`mlp`) and
its logistic training (:func:`train_discriminator`). Model-based GAIL's
discriminator (:class:`avrisk.learning.imitation.mgail.Discriminator`) is
built from them, and the closed-loop stage
(:mod:`avrisk.learning.training.closed_loop`) computes the features of its
simulated followers with :func:`transition_features`.

Discriminator input (compact, computed identically from the human record and
the simulated trace): ``x_t = (v_t [m/s], gap_t [m], v_leader,t - v_t [m/s],
a_{t-1} [m/s^2], a_t [m/s^2])`` with the *realised* accelerations ``a_t =
(v_{t+1} - v_t) / dt``; ``a_{t-1}`` makes jerk visible. It is defined for
``t >= 1``; the first step gets reward 0. Inputs are standardised by the human
statistics.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from avrisk.learning.replay import DT, CarFollowingWindows

__all__ = [
    "human_transitions",
    "mlp",
    "train_discriminator",
    "transition_features",
]


def mlp(n_in: int, hidden: int, n_out: int = 1) -> nn.Sequential:
    """Two tanh hidden layers of ``hidden`` units (discriminator, value)."""
    return nn.Sequential(
        nn.Linear(n_in, hidden),
        nn.Tanh(),
        nn.Linear(hidden, hidden),
        nn.Tanh(),
        nn.Linear(hidden, n_out),
    )


def transition_features(v: Tensor, v_l: Tensor, gap: Tensor) -> Tensor:
    """Discriminator inputs of every step of car-following tracks.

    Differentiable: MGAIL (:mod:`avrisk.learning.imitation.mgail`)
    back-propagates the discriminator's reward through them into a simulated
    follower.

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
