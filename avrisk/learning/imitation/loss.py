"""The imitation loss: weighted Gaussian negative log-likelihood of demonstrations.

The driver network outputs a Gaussian over ``(accel, steer)``; training
minimises the demonstrated actions' negative log-likelihood, each target
weighted by its demonstration weight (0 where the target is unknown).
:func:`weighted_nll` is that loss on a batch (also for ``m`` heads at once),
:func:`imitation_nll` its value per source on a whole set.
"""

from __future__ import annotations

import numpy as np
import torch

from avrisk.agents.drivers.network import ActionDistribution, DriverNet
from avrisk.learning.imitation.demonstrations import SOURCE_NAMES, Demonstrations

__all__ = ["demonstration_tensors", "imitation_nll", "weighted_nll"]


def weighted_nll(
    dist: ActionDistribution,
    accel: torch.Tensor,
    steer: torch.Tensor,
    w_accel: torch.Tensor,
    w_steer: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Sum of weighted NLLs and sum of weights (both broadcast over heads)."""
    lp_a, lp_s = dist.log_prob(accel, steer)
    total = -(w_accel * lp_a + w_steer * lp_s).sum(-1)
    return total, (w_accel + w_steer).sum(-1)


def demonstration_tensors(demos: Demonstrations) -> dict[str, torch.Tensor]:
    """Features, targets and weights as float32 tensors (sharing memory if float32).

    Keys ``"features"``, ``"accel"``, ``"steer"``, ``"w_accel"``, ``"w_steer"``.
    """
    return {
        "features": torch.from_numpy(np.ascontiguousarray(demos.features, np.float32)),
        "accel": torch.from_numpy(demos.accel.astype(np.float32)),
        "steer": torch.from_numpy(demos.steer.astype(np.float32)),
        "w_accel": torch.from_numpy(demos.accel_weight.astype(np.float32)),
        "w_steer": torch.from_numpy(demos.steer_weight.astype(np.float32)),
    }


def imitation_nll(
    net: DriverNet,
    demos: Demonstrations,
    xi: torch.Tensor | None = None,
    *,
    batch: int = 65536,
) -> dict[str, float]:
    """Mean Gaussian negative log-likelihood of the demonstrated actions.

    Parameters
    ----------
    net : DriverNet
    demos : Demonstrations
    xi : Tensor of shape (XI_DIM,), optional
        Last layer; default the network's own.
    batch : int, default=65536
        Rows per forward pass.

    Returns
    -------
    dict of str to float
        ``"<source>/accel"`` and ``"<source>/steer"`` NLL per row with a target
        [nats], for each source present, and ``"loss"``: the weighted mean
        that training minimises.
    """
    t = demonstration_tensors(demos)
    n = len(demos)
    lp_a = torch.empty(n)
    lp_s = torch.empty(n)
    with torch.no_grad():
        for s in range(0, n, batch):
            dist = net(t["features"][s : s + batch], xi)
            a, b = dist.log_prob(t["accel"][s : s + batch], t["steer"][s : s + batch])
            lp_a[s : s + batch], lp_s[s : s + batch] = a, b
    wa, ws = t["w_accel"], t["w_steer"]
    out = {
        "loss": float(-(wa * lp_a + ws * lp_s).sum() / (wa + ws).sum().clamp_min(1e-12))
    }
    for code, name in SOURCE_NAMES.items():
        m = torch.from_numpy(demos.source == code)
        for target, lp, w in (("accel", lp_a, wa), ("steer", lp_s, ws)):
            sel = m & (w > 0)
            if bool(sel.any()):
                out[f"{name}/{target}"] = float(-lp[sel].mean())
    return out
