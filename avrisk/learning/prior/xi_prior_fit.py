"""``P0(xi)`` from the bootstrap heads, and the validation of the heads and ``mu0``.

The last stage of :func:`~avrisk.learning.training.train.train_drivers`: the ``m``
bootstrap heads (:mod:`avrisk.learning.prior.bootstrap_heads`) are the samples to
which :func:`~avrisk.learning.prior.glasso.fit_sparse_gaussian` fits
``xi ~ N(mu0, Sigma0)`` with a sparse precision (:func:`fit_xi_prior`);
:func:`validation_nll` measures how well the shared head, ``mu0`` and every
head imitate the validation demonstrations.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import XiPrior
from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.imitation.loss import imitation_nll
from avrisk.learning.prior.glasso import fit_sparse_gaussian
from avrisk.learning.train_config import Progress, TrainConfig, TrainEvent

__all__ = ["fit_xi_prior", "validation_nll"]


def fit_xi_prior(
    heads: NDArray[np.float64],
    config: TrainConfig,
    seed: int,
    progress: Progress | None = None,
) -> XiPrior:
    """Ledoit-Wolf + graphical-lasso Gaussian of the heads, as an ``XiPrior``.

    Parameters
    ----------
    heads : ndarray of shape (m, XI_DIM)
        The bootstrap heads (the prior's members).
    config : TrainConfig
        ``target_density`` of the precision, and ``max_shift`` (recorded).
    seed : int
        Recorded in the metadata.
    progress : callable, optional
        Receives a ``"prior"`` :class:`TrainEvent`.

    Returns
    -------
    XiPrior
        Its metadata: the fit's
        (:meth:`~avrisk.learning.prior.glasso.SparseGaussianFit.to_meta`), the seed,
        ``max_shift`` and the median and largest spread of the members.
    """
    fit = fit_sparse_gaussian(heads, target_density=config.target_density)
    meta = {
        **fit.to_meta(),
        "seed": seed,
        "max_shift": config.max_shift,
        "member_std_median": float(np.median(heads.std(axis=0, ddof=1))),
        "member_std_max": float(heads.std(axis=0, ddof=1).max()),
    }
    if progress is not None:
        progress(
            TrainEvent("prior", 1, 1, {"sparsity": fit.sparsity, "alpha": fit.alpha})
        )
    return XiPrior(mean=fit.mean, precision=fit.precision, members=heads, meta=meta)


def validation_nll(
    net: DriverNet, val: Demonstrations, prior: XiPrior
) -> dict[str, Any]:
    """Validation NLL of the shared head, of ``mu0`` and of every member.

    Parameters
    ----------
    net : DriverNet
    val : Demonstrations
    prior : XiPrior

    Returns
    -------
    dict
        ``"shared_head"`` and ``"mu0"``: :func:`imitation_nll` per source and
        target; ``"members"``: every member's weighted mean loss.
    """
    mu0 = torch.as_tensor(prior.mean, dtype=torch.float32)
    return {
        "shared_head": imitation_nll(net, val),
        "mu0": imitation_nll(net, val, mu0),
        "members": [
            imitation_nll(net, val, torch.as_tensor(h, dtype=torch.float32))["loss"]
            for h in prior.members
        ],
    }
