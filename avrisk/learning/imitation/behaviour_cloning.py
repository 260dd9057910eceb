"""Behaviour cloning: a new driver network fitted to demonstrations.

:func:`fit_driver_net` is the first stage of
:func:`~avrisk.learning.training.train.train_drivers`: a :class:`DriverNet` whose input
standardisation (:func:`fit_input_normalization`) and action scales
(:func:`fit_action_scale`) come from the training demonstrations, trained as a
whole (trunk and shared head) by :func:`behaviour_cloning`, Adam on the
weighted Gaussian NLL of :mod:`avrisk.learning.imitation.loss` with a cosine
learning-rate schedule. DAgger (:mod:`avrisk.learning.imitation.dagger`) refits with the
same function.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.features import FEATURE_NAMES, INDICATOR_FEATURES
from avrisk.agents.drivers.network import DriverNet
from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.imitation.loss import (
    demonstration_tensors,
    imitation_nll,
    weighted_nll,
)
from avrisk.learning.train_config import Progress, TrainConfig, TrainEvent

__all__ = [
    "behaviour_cloning",
    "fit_action_scale",
    "fit_driver_net",
    "fit_input_normalization",
]


def fit_input_normalization(
    features: NDArray[Any],
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Per-feature centre and scale for the network's input standardisation.

    Indicators keep centre 0 and scale 1; constant features get scale 1.

    Parameters
    ----------
    features : ndarray of shape (N, N_FEATURES)

    Returns
    -------
    mean, scale : ndarray of float32, shape (N_FEATURES,)
    """
    x = np.asarray(features, dtype=np.float64)
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale = np.where(scale > 1e-6, scale, 1.0)
    for name in INDICATOR_FEATURES:
        k = FEATURE_NAMES.index(name)
        mean[k], scale[k] = 0.0, 1.0
    return mean.astype(np.float32), scale.astype(np.float32)


def fit_action_scale(demos: Demonstrations) -> tuple[float, float]:
    """Weighted standard deviations of the targets ``(s_a [m/s^2], s_s [rad])``."""

    def wstd(y: NDArray[Any], w: NDArray[Any], fallback: float) -> float:
        if w.sum() <= 0:
            return fallback
        mu = np.average(y, weights=w)
        return float(
            max(np.sqrt(np.average((y - mu) ** 2, weights=w)), 1e-3 * fallback)
        )

    return wstd(demos.accel, demos.accel_weight, 1.0), wstd(
        demos.steer, demos.steer_weight, 0.02
    )


def behaviour_cloning(
    net: DriverNet,
    demos: Demonstrations,
    *,
    epochs: int = 12,
    batch_size: int = 1024,
    lr: float = 1e-3,
    weight_decay: float = 1e-5,
    seed: int = 0,
    val: Demonstrations | None = None,
    progress: Progress | None = None,
) -> list[dict[str, float]]:
    """Fit the whole network to demonstrations by weighted Gaussian NLL (Adam).

    Parameters
    ----------
    net : DriverNet
        Trained in place (its input and action scales are kept).
    demos : Demonstrations
    epochs, batch_size : int
    lr, weight_decay : float
        Adam settings.
    seed : int, default=0
        Seeds the shuffling.
    val : Demonstrations, optional
        Evaluated after every epoch (:func:`imitation_nll`).
    progress : callable, optional
        Receives a :class:`TrainEvent` after every epoch.

    Returns
    -------
    list of dict
        Per epoch: ``"epoch"``, ``"train_loss"`` and ``"val/..."`` entries.
    """
    t = demonstration_tensors(demos)
    n = len(demos)
    gen = torch.Generator().manual_seed(seed)
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs)
    history = []
    net.train()
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        total, weight = 0.0, 0.0
        for s in range(0, n, batch_size):
            idx = perm[s : s + batch_size]
            dist = net(t["features"][idx])
            nll, w = weighted_nll(
                dist,
                t["accel"][idx],
                t["steer"][idx],
                t["w_accel"][idx],
                t["w_steer"][idx],
            )
            loss = nll / w.clamp_min(1e-12)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(nll.detach())
            weight += float(w)
        sched.step()
        row = {"epoch": float(epoch + 1), "train_loss": total / max(weight, 1e-12)}
        if val is not None:
            net.eval()
            row.update({f"val/{k}": v for k, v in imitation_nll(net, val).items()})
            net.train()
        history.append(row)
        if progress is not None:
            progress(TrainEvent("trunk", epoch + 1, epochs, row))
    net.eval()
    return history


def fit_driver_net(
    train: Demonstrations,
    val: Demonstrations,
    config: TrainConfig,
    seed: int,
    progress: Progress | None = None,
) -> tuple[DriverNet, list[dict[str, float]]]:
    """A new network, scaled to ``train`` and fitted to it by behaviour cloning.

    Parameters
    ----------
    train, val : Demonstrations
        Training and validation demonstrations.
    config : TrainConfig
        ``trunk_epochs``, ``batch_size``, ``lr``, ``weight_decay`` and ``head``.
    seed : int
        Seeds the shuffling (the initial weights come from torch's global
        generator).
    progress : callable, optional
        Receives a ``"trunk"`` :class:`TrainEvent` after every epoch.

    Returns
    -------
    net : DriverNet
    history : list of dict
        As returned by :func:`behaviour_cloning`.
    """
    mean, scale = fit_input_normalization(train.features)
    net = DriverNet(mean, scale, fit_action_scale(train), head=config.head)
    history = behaviour_cloning(
        net,
        train,
        epochs=config.trunk_epochs,
        batch_size=config.batch_size,
        lr=config.lr,
        weight_decay=config.weight_decay,
        seed=seed,
        val=val,
        progress=progress,
    )
    return net, history
