"""Sampling a learned driver's actions: autocorrelated noise, a reproducible exp.

``action_t = mean_t + c * std_t * eps_t`` with standardised noise
``eps_t = rho eps_{t-1} + sqrt(1 - rho^2) z_t`` (:func:`ar1_noise`,
:func:`sample_actions`; the model: :mod:`avrisk.agents.drivers.driver`). The
standard deviation is ``exp(log_var / 2)`` by :func:`reproducible_exp`, which
rounds the same wherever an element sits in a tensor, so that a rollout's
actions are the same alone or in any batch.
"""

from __future__ import annotations

import torch
from torch import Tensor

from avrisk.agents.drivers.network import ActionDistribution
from avrisk.tensors.mathops import sqrt

__all__ = [
    "DRIVER_NOISE_STREAM",
    "EGO_NOISE_STREAM",
    "ar1_noise",
    "innovations_at",
    "reproducible_exp",
    "sample_actions",
]

#: Counter-based noise stream of the environment drivers.
DRIVER_NOISE_STREAM = 0x4C44  # "LD"
#: Noise stream of the learned ego (distinct from the drivers').
EGO_NOISE_STREAM = 0x4C45

_LOG2E = 1.44269504088896341
_LN2_HI, _LN2_LO = 0.693359375, -2.12194440e-4
_EXP_POLY = (
    1.9875691500e-4,
    1.3981999507e-3,
    8.3334519073e-3,
    4.1665795894e-2,
    1.6666665459e-1,
    5.0000001201e-1,
)


def reproducible_exp(x: Tensor) -> Tensor:
    """``exp(x)`` from IEEE basic operations only (bit-reproducible).

    ``torch.exp`` may round an element differently depending on where it sits
    in a tensor (vectorised body or scalar tail); this function, like
    :mod:`avrisk.tensors.mathops`, uses only ``+ - * /``, ``round`` and an exact
    power of two, so it does not (Cephes ``expf``: a few ulp in float32).

    Parameters
    ----------
    x : Tensor of shape (...)
        Float32 or float64; clipped to ``[-87, 88]``.

    Returns
    -------
    Tensor of shape (...)

    Examples
    --------
    >>> import torch
    >>> round(reproducible_exp(torch.tensor([1.0]))[0].item(), 5)
    2.71828
    """
    x = torch.clamp(x, -87.0, 88.0)
    k = torch.round(x * _LOG2E)
    r = x - k * _LN2_HI
    r = r - k * _LN2_LO
    p = r * 0.0 + _EXP_POLY[0]
    for c in _EXP_POLY[1:]:
        p = p * r + c
    y = p * (r * r) + r + 1.0
    # 2**k exactly, by building the float from its exponent bits.
    ki = k.to(torch.int32 if x.dtype == torch.float32 else torch.int64)
    if x.dtype == torch.float32:
        two_k = ((ki + 127) << 23).view(torch.float32)
    elif x.dtype == torch.float64:
        two_k = ((ki + 1023) << 52).view(torch.float64)
    else:
        raise TypeError(f"reproducible_exp takes float32 or float64; got {x.dtype}")
    return y * two_k


def ar1_noise(
    previous: Tensor | None, z: Tensor, rho: Tensor, start: bool | Tensor = False
) -> Tensor:
    """Standardised action noise, autocorrelated over steps.

    Parameters
    ----------
    previous : Tensor of shape (B, ..., 2) or None
        Last step's noise; None starts the process (``z`` itself).
    z : Tensor of shape (B, ..., 2)
        This step's standard-normal draw (the simulator's, counter-based).
    rho : Tensor of shape (2,)
        Autocorrelation per action in ``[0, 1)``.
    start : bool or Tensor of bool, shape () or (B,), default=False
        Start the process here (``z`` itself) whatever ``previous`` holds; a
        tensor keeps the choice on the device (the simulator's compiled step),
        one per rollout when the rollouts are at different steps.

    Returns
    -------
    Tensor of shape (B, ..., 2)
        Marginally standard normal at every step, in the dtype of ``z``.
    """
    if previous is None or start is True:
        return z
    rho = rho.to(z.dtype)
    mixed = rho * previous + sqrt(1.0 - rho * rho) * z
    if not isinstance(start, Tensor):
        return mixed
    return torch.where(start.reshape(start.shape + (1,) * (z.dim() - 1)), z, mixed)


def innovations_at(innovations: Tensor, step: int | Tensor) -> Tensor:
    """Each rollout's innovations at its step.

    Parameters
    ----------
    innovations : Tensor of shape (B, T, C, 2)
        Every step's standard-normal innovations of ``C`` vehicles.
    step : int or Tensor of int64, shape () or (B,)
        The step, one for all or one per rollout (``0 <= step < T``).

    Returns
    -------
    Tensor of shape (B, C, 2)
    """
    batch = innovations.shape[0]
    index = torch.as_tensor(step, device=innovations.device).expand(batch)
    return innovations[torch.arange(batch, device=innovations.device), index]


def sample_actions(
    dist: ActionDistribution, eps: Tensor | None, scale: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """Actions from per-vehicle Gaussians and standardised noise.

    Parameters
    ----------
    dist : ActionDistribution
        Fields of shape (B,) or (B, A).
    eps : Tensor of shape (B, 2) or (B, A, 2), or None
        Standardised noise (:func:`ar1_noise`); None returns the means.
    scale : Tensor of shape (2,), optional
        Factor on the standard deviations (default 1).

    Returns
    -------
    accel : Tensor of shape (B,) or (B, A)
        Acceleration [m/s^2].
    steer : Tensor of shape (B,) or (B, A)
        Steering [rad].
    """
    accel, steer = dist.accel_mean, dist.steer_mean
    if eps is None:
        return accel, steer
    eps = eps.to(accel.dtype)
    if scale is not None:
        eps = eps * scale.to(accel.dtype)
    accel = accel + reproducible_exp(0.5 * dist.accel_log_var) * eps[..., 0]
    steer = steer + reproducible_exp(0.5 * dist.steer_log_var) * eps[..., 1]
    return accel, steer
