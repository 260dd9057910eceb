"""Counter-based random numbers: a pure function of (seed, step, stream, index).

Stochastic drivers and policies must not share a ``torch.Generator`` across a
batch: the numbers a rollout received would then depend on its position in the
batch and on the batch size. Instead every random number is a hash of
``(seed of its rollout, time step, stream, element index)``, computed with
64-bit integer arithmetic (SplitMix64 finaliser [1]_), which is exact and
identical on every device. A rollout therefore receives the same noise alone,
in any batch, in any order, on CPU or GPU.

Streams separate independent uses within a step (for example 0 for throttle
noise, 1 for steering noise); pick one constant per use.

Examples
--------
>>> import torch
>>> seeds = torch.tensor([7, 8])
>>> u = uniform(seeds, step=3, stream=0, shape=(6,))
>>> u.shape
torch.Size([2, 6])
>>> bool(torch.equal(u[1], uniform(seeds[1:], step=3, stream=0, shape=(6,))[0]))
True

References
----------
.. [1] G. L. Steele, D. Lea, C. H. Flood, "Fast splittable pseudorandom number
   generators", OOPSLA 2014.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from avrisk.tensors.mathops import log, sincos, sqrt

__all__ = ["normal", "random_bits", "uniform"]


def _signed(u: int) -> int:
    """A Python integer wrapped to int64, as int64 tensor arithmetic wraps."""
    u &= (1 << 64) - 1
    return u - (1 << 64) if u >= 1 << 63 else u


_GAMMA = _signed(0x9E3779B97F4A7C15)
_M1 = _signed(0xBF58476D1CE4E5B9)
_M2 = _signed(0x94D049BB133111EB)
_STEP_KEY = _signed(0xD1B54A32D192ED03)
_STREAM_KEY = _signed(0x8CB92BA72F3D8DD7)


def _shr(z: Tensor, k: int) -> Tensor:
    """Logical right shift of int64 (torch's ``>>`` is arithmetic)."""
    return (z >> k) & ((1 << (64 - k)) - 1)


def _mix(z: Tensor) -> Tensor:
    z = (z ^ _shr(z, 30)) * _M1  # int64 products wrap modulo 2**64
    z = (z ^ _shr(z, 27)) * _M2
    return z ^ _shr(z, 31)


def random_bits(
    seeds: Tensor, step: int | Tensor, stream: int, shape: tuple[int, ...] = ()
) -> Tensor:
    """64 random bits per element, a pure function of its coordinates.

    Parameters
    ----------
    seeds : Tensor of int64, shape (B,)
        One seed per rollout.
    step : int or Tensor of int64, shape () or (B,)
        Time step index (``>= 0``); a 0-d tensor gives the same numbers, a
        tensor of shape (B,) one step per rollout.
    stream : int
        Independent stream within a step (``>= 0``).
    shape : tuple of int, default=()
        Trailing shape of the numbers drawn per rollout (e.g. ``(A,)``).

    Returns
    -------
    Tensor of int64, shape (B, *shape)
    """
    key = _mix(seeds.to(torch.int64) * _GAMMA + _GAMMA)
    salt: int | Tensor
    if isinstance(step, Tensor):  # int64 products wrap as _signed does
        salt = step.to(torch.int64) * _STEP_KEY + _signed(stream * _STREAM_KEY)
    else:
        salt = _signed(step * _STEP_KEY + stream * _STREAM_KEY)
    key = _mix(key ^ salt)
    n = math.prod(shape)
    index = torch.arange(1, n + 1, dtype=torch.int64, device=seeds.device).reshape(
        shape
    )
    return _mix(key.reshape(key.shape + (1,) * len(shape)) + index * _GAMMA)


def uniform(
    seeds: Tensor,
    step: int | Tensor,
    stream: int,
    shape: tuple[int, ...] = (),
    *,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Uniform numbers on the open interval (0, 1).

    Parameters
    ----------
    seeds, step, stream, shape
        As in :func:`random_bits`.
    dtype : torch.dtype, default=torch.float32

    Returns
    -------
    Tensor of shape (B, *shape)
        Multiples of ``2**-23`` offset by half a step: exact in float32.
    """
    k = _shr(random_bits(seeds, step, stream, shape), 41)  # 23 bits
    return (k.to(dtype) + 0.5) * (2.0**-23)


def normal(
    seeds: Tensor,
    step: int | Tensor,
    stream: int,
    shape: tuple[int, ...] = (),
    *,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Standard normal numbers (Box-Muller on two counter-based uniforms).

    Parameters
    ----------
    seeds, step, stream, shape
        As in :func:`random_bits`; ``stream`` and ``stream + 1_000_003`` are used.
    dtype : torch.dtype, default=torch.float32

    Returns
    -------
    Tensor of shape (B, *shape)
    """
    u1 = uniform(seeds, step, stream, shape, dtype=dtype)
    u2 = uniform(seeds, step, stream + 1_000_003, shape, dtype=dtype)
    radius = sqrt(-2.0 * log(u1))
    _, c = sincos((2.0 * math.pi) * u2)
    return radius * c
