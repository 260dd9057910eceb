"""The flat layout of ``xi``: the driver network's last layer as 404 numbers.

The last layer maps the 100 hidden units to 4 outputs (:data:`OUTPUT_NAMES`):
``W`` of shape (4, 100) and ``b`` of shape (4,). ``xi`` is the row-major
weight matrix followed by the biases::

    xi[o * 100 + h] = W[o, h]      o = 0..3, h = 0..99
    xi[400 + o]     = b[o]

so ``xi[0:100]`` is the acceleration-mean row, ``xi[100:200]`` the
steering-mean row, ``xi[200:300]`` and ``xi[300:400]`` the two log-variance
rows, ``xi[400:404]`` the biases. The same layout names the ``xi.K`` columns of
a scenario sample (:mod:`avrisk.scenario.params`).

Examples
--------
>>> import torch
>>> XI_DIM, XI_NAMES[0], XI_NAMES[400]
(404, 'w.accel_mean.0', 'b.accel_mean')
>>> w, b = torch.randn(4, 100), torch.randn(4)
>>> w2, b2 = unpack_xi(pack_xi(w, b))
>>> bool(torch.equal(w, w2) and torch.equal(b, b2))
True
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = [
    "N_HIDDEN_LAST",
    "N_OUTPUTS",
    "OUTPUT_NAMES",
    "XI_DIM",
    "XI_NAMES",
    "pack_xi",
    "unpack_xi",
    "xi_bias_slice",
    "xi_row_slice",
]

#: Width of the last hidden layer (paper, appendix B).
N_HIDDEN_LAST = 100

#: Network outputs, in order: Gaussian means [m/s^2, rad] and log-variances
#: [log (m/s^2)^2, log rad^2], each in the network's standardised action scale
#: (see :class:`avrisk.agents.drivers.network.DriverNet`).
OUTPUT_NAMES: tuple[str, ...] = (
    "accel_mean",
    "steer_mean",
    "accel_log_var",
    "steer_log_var",
)

#: Number of outputs (4).
N_OUTPUTS = len(OUTPUT_NAMES)

#: Length of ``xi``: ``N_OUTPUTS * (N_HIDDEN_LAST + 1) = 404``.
XI_DIM = N_OUTPUTS * N_HIDDEN_LAST + N_OUTPUTS

#: Name of every ``xi`` entry, in layout order.
XI_NAMES: tuple[str, ...] = (
    *(f"w.{o}.{h}" for o in OUTPUT_NAMES for h in range(N_HIDDEN_LAST)),
    *(f"b.{o}" for o in OUTPUT_NAMES),
)


def xi_row_slice(output: str) -> slice:
    """Entries of ``xi`` holding the weight row of one output.

    Parameters
    ----------
    output : str
        One of :data:`OUTPUT_NAMES`.

    Returns
    -------
    slice
        Of length ``N_HIDDEN_LAST``.
    """
    o = OUTPUT_NAMES.index(output)
    return slice(o * N_HIDDEN_LAST, (o + 1) * N_HIDDEN_LAST)


def xi_bias_slice() -> slice:
    """Entries of ``xi`` holding the four biases, ``slice(400, 404)``."""
    return slice(N_OUTPUTS * N_HIDDEN_LAST, XI_DIM)


def pack_xi(weight: Tensor, bias: Tensor) -> Tensor:
    """Flatten last-layer weights and biases into ``xi``.

    Parameters
    ----------
    weight : Tensor of shape (..., N_OUTPUTS, N_HIDDEN_LAST)
    bias : Tensor of shape (..., N_OUTPUTS)

    Returns
    -------
    Tensor of shape (..., XI_DIM)
    """
    if weight.shape[-2:] != (N_OUTPUTS, N_HIDDEN_LAST):
        raise ValueError(
            f"weight must have shape (..., {N_OUTPUTS}, {N_HIDDEN_LAST}); "
            f"got {tuple(weight.shape)}"
        )
    if bias.shape[-1:] != (N_OUTPUTS,) or bias.shape[:-1] != weight.shape[:-2]:
        raise ValueError(
            f"bias must have shape {tuple(weight.shape[:-2]) + (N_OUTPUTS,)}; "
            f"got {tuple(bias.shape)}"
        )
    return torch.cat([weight.flatten(-2), bias], dim=-1)


def unpack_xi(xi: Tensor) -> tuple[Tensor, Tensor]:
    """Split ``xi`` into last-layer weights and biases (views, no copy).

    Parameters
    ----------
    xi : Tensor of shape (..., XI_DIM)

    Returns
    -------
    weight : Tensor of shape (..., N_OUTPUTS, N_HIDDEN_LAST)
    bias : Tensor of shape (..., N_OUTPUTS)
    """
    if xi.shape[-1] != XI_DIM:
        raise ValueError(f"xi must have shape (..., {XI_DIM}); got {tuple(xi.shape)}")
    n = N_OUTPUTS * N_HIDDEN_LAST
    weight = xi[..., :n].unflatten(-1, (N_OUTPUTS, N_HIDDEN_LAST))
    return weight, xi[..., n:]
