"""The bootstrap ensemble: ``m`` heads refitted on resamples, trunk frozen.

After behaviour cloning and DAgger, the last layer ``xi`` of the driver
network is refitted ``m`` times, each on a bootstrap resample of the training
episodes (within each source), with the trunk frozen so that the heads are
comparable. The ``m`` heads are the members to which
:mod:`avrisk.learning.prior.xi_prior_fit` fits ``P0(xi)``.
"""

from __future__ import annotations

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import pack_xi
from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.imitation.loss import demonstration_tensors, weighted_nll
from avrisk.learning.train_config import Progress, TrainEvent

__all__ = ["bootstrap_heads", "centre_heads"]


def _bootstrap_counts(
    episode: NDArray[np.int64],
    source: NDArray[np.int8],
    n_members: int,
    rng: np.random.Generator,
) -> NDArray[np.float32]:
    """Per-member row multiplicities from resampling episodes within each source."""
    uniq, inverse = np.unique(episode, return_inverse=True)
    ep_source = np.zeros(len(uniq), np.int8)
    ep_source[inverse] = source
    counts = np.zeros((n_members, len(uniq)), np.float32)
    for code in np.unique(ep_source):
        eps = np.flatnonzero(ep_source == code)
        for k in range(n_members):
            draw = rng.integers(0, len(eps), len(eps))
            np.add.at(counts[k], eps[draw], 1.0)
    return counts[:, inverse]  # (m, N)


def bootstrap_heads(
    net: DriverNet,
    demos: Demonstrations,
    n_members: int = 20,
    *,
    epochs: int = 20,
    batch_size: int = 4096,
    lr: float = 3e-4,
    seed: int = 0,
    progress: Progress | None = None,
) -> tuple[NDArray[np.float64], list[dict[str, float]]]:
    """Refit the last layer on ``m`` bootstrap resamples, trunk frozen.

    Episodes (not rows) are resampled with replacement within each source; all
    heads start from the network's head and see the same minibatch sequence,
    so they differ only through their resample. All heads train together: one
    ``(m, n, 100) x (m, 100, 4)`` product per step.

    Parameters
    ----------
    net : DriverNet
        Trained trunk; not modified.
    demos : Demonstrations
    n_members : int, default=20
    epochs, batch_size : int
    lr : float
        Adam learning rate.
    seed : int, default=0
    progress : callable, optional
        Receives a :class:`TrainEvent` after every epoch.

    Returns
    -------
    heads : ndarray of shape (m, XI_DIM)
        Each member's ``xi``.
    history : list of dict
        Per epoch: ``"epoch"``, ``"train_loss"`` (mean over heads).
    """
    rng = np.random.default_rng(seed)
    t = demonstration_tensors(demos)
    n = len(demos)
    with torch.no_grad():
        hidden = torch.cat(
            [net.trunk(t["features"][s : s + 65536]) for s in range(0, n, 65536)]
        )
    mult = torch.from_numpy(
        _bootstrap_counts(demos.episode, demos.source, n_members, rng)
    )
    weight = net.last.weight.detach().clone().expand(n_members, -1, -1).contiguous()
    bias = net.last.bias.detach().clone().expand(n_members, -1).contiguous()
    weight.requires_grad_(True)
    bias.requires_grad_(True)
    opt = torch.optim.Adam([weight, bias], lr=lr)
    gen = torch.Generator().manual_seed(seed + 1)
    history = []
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        total = 0.0
        steps = 0
        for s in range(0, n, batch_size):
            idx = perm[s : s + batch_size]
            raw = torch.einsum("nh,moh->mno", hidden[idx], weight) + bias[:, None, :]
            dist = net.distribution(raw, t["features"][idx])
            m = mult[:, idx]
            nll, w = weighted_nll(
                dist,
                t["accel"][idx],
                t["steer"][idx],
                m * t["w_accel"][idx],
                m * t["w_steer"][idx],
            )
            loss = (nll / w.clamp_min(1e-12)).sum()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(loss.detach()) / n_members
            steps += 1
        row = {"epoch": float(epoch + 1), "train_loss": total / max(steps, 1)}
        history.append(row)
        if progress is not None:
            progress(TrainEvent("heads", epoch + 1, epochs, row))
    heads = pack_xi(weight.detach(), bias.detach()).to(torch.float64).numpy()
    return heads, history


def centre_heads(heads: NDArray[np.float64], net: DriverNet) -> NDArray[np.float64]:
    """Move the members together so that their mean is the network's head.

    The bootstrap heads are refitted by one-step imitation, which pulls them
    back towards the behaviour-cloning optimum; after closed-loop training
    the network's own head is the one to centre ``P0(xi)`` on. The members'
    spread around their mean (the estimation uncertainty) is kept.

    Parameters
    ----------
    heads : ndarray of shape (m, XI_DIM)
    net : DriverNet

    Returns
    -------
    ndarray of shape (m, XI_DIM)
    """
    centre = net.default_xi.to(torch.float64).numpy()
    return heads - heads.mean(axis=0) + centre
