"""Reproducible elementary functions built from IEEE basic operations only.

Why not ``torch.sin``? Its result for one element may depend on where that
element sits in a tensor (vectorised body or scalar tail), on the CPU's
instruction set (different SLEEF variants) and on the device (CUDA's ``sinf``
is not SLEEF's). A rollout is a long feedback loop with discrete decisions
(lane changes, crash or not), so a one-ulp difference can change its result.
The functions here use only ``+ - * /``, ``round``, ``floor``, comparisons
and ``where``, which IEEE 754 rounds correctly everywhere, and a square root
that is correctly rounded too (:func:`sqrt`); their results are therefore
bit-identical for any batch size, batch position, CPU or GPU, eager or
``torch.compile`` (float32; in float64 only ``sqrt`` may differ by an ulp
between those). That is what lets the simulator promise that a rollout's
result depends only on its own inputs.

Accuracy is that of single precision (Cephes ``sinf``/``atanf``
polynomials): a few ulp in float32, about 1e-7 relative in float64.

References
----------
.. [1] S. L. Moshier, Cephes Math Library, ``sinf.c``, ``atanf.c`` (1984-2000).
.. [2] W. J. Cody, W. Waite, *Software Manual for the Elementary Functions*,
   Prentice-Hall, 1980 (argument reduction in three parts).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["asin", "atan", "log", "sinc", "sincos", "sqrt", "wrap_angle"]

_TWO_OVER_PI = 0.636619772367581343
# pi/2 split in three float32-exact parts (Cephes DP1..DP3 doubled).
_PIO2_1 = 1.5703125
_PIO2_2 = 4.837512969970703125e-4
_PIO2_3 = 7.54978995489188216e-8

_S1, _S2, _S3 = -1.9515295891e-4, 8.3321608736e-3, -1.6666654611e-1
_C1, _C2, _C3 = 2.443315711809948e-5, -1.388731625493765e-3, 4.166664568298827e-2

_TAN_3PI_8 = 2.414213562373095
_TAN_PI_8 = 0.4142135623730950
_A1, _A2, _A3, _A4 = (
    8.05374449538e-2,
    -1.38776856032e-1,
    1.99777106478e-1,
    -3.33329491539e-1,
)


def sincos(x: Tensor) -> tuple[Tensor, Tensor]:
    """Sine and cosine of an angle, bit-reproducible.

    Parameters
    ----------
    x : Tensor of shape (...)
        Angle [rad]. Accurate for ``|x| < 1e4``.

    Returns
    -------
    sin, cos : Tensor of shape (...)
    """
    q = torch.round(x * _TWO_OVER_PI)
    r = x - q * _PIO2_1
    r = r - q * _PIO2_2
    r = r - q * _PIO2_3  # r in [-pi/4, pi/4]
    z = r * r
    s = ((_S1 * z + _S2) * z + _S3) * z * r + r
    c = ((_C1 * z + _C2) * z + _C3) * z * z - 0.5 * z + 1.0
    quadrant = q.to(torch.int64) & 3  # two's complement: also right for q < 0
    swap = (quadrant & 1) == 1
    sin_r = torch.where(swap, c, s)
    cos_r = torch.where(swap, s, c)
    sin = torch.where(quadrant >= 2, -sin_r, sin_r)
    cos = torch.where((quadrant == 1) | (quadrant == 2), -cos_r, cos_r)
    return sin, cos


def atan(x: Tensor) -> Tensor:
    """Arc tangent, bit-reproducible; ``atan(+-inf) = +-pi/2``.

    Parameters
    ----------
    x : Tensor of shape (...)

    Returns
    -------
    Tensor of shape (...)
        Angle in ``[-pi/2, pi/2]`` [rad].
    """
    ax = torch.abs(x)
    big = ax > _TAN_3PI_8
    mid = ax > _TAN_PI_8
    # Only the selected branch is used; -1 / ax divides by a masked ax so that
    # no branch holds inf (whose gradient would be NaN under autograd).
    inv = -1.0 / torch.where(big, ax, 1.0)
    xr = torch.where(big, inv, torch.where(mid, (ax - 1.0) / (ax + 1.0), ax))
    y0 = torch.where(big, math.pi / 2, torch.where(mid, math.pi / 4, 0.0))
    z = xr * xr
    y = (((_A1 * z + _A2) * z + _A3) * z + _A4) * z * xr + xr
    y = y + y0
    return torch.where(x < 0, -y, y)


def sqrt(x: Tensor) -> Tensor:
    """Square root, correctly rounded in float32, bit-reproducible.

    ``torch.sqrt`` on CPU is not correctly rounded in float32 (it is off by
    one ulp for about one element in six, unlike compiled code or CUDA). The
    float64 square root of a float32 number, rounded once to float32, is
    correctly rounded (the exact root is never within a few float64 ulp of a
    float32 rounding boundary), whichever float64 routine computes it.
    Float64 input uses ``torch.sqrt`` directly.

    Parameters
    ----------
    x : Tensor of shape (...)
        Non-negative.

    Returns
    -------
    Tensor of shape (...)
        Same dtype as ``x``.
    """
    if x.dtype == torch.float64:
        return torch.sqrt(x)
    return torch.sqrt(x.to(torch.float64)).to(x.dtype)


def asin(x: Tensor) -> Tensor:
    """Arc sine of ``x`` clipped to ``[-1, 1]``, bit-reproducible.

    Parameters
    ----------
    x : Tensor of shape (...)

    Returns
    -------
    Tensor of shape (...)
        Angle in ``[-pi/2, pi/2]`` [rad].
    """
    x = torch.clamp(x, -1.0, 1.0)
    return atan(x / sqrt(1.0 - x * x))


def wrap_angle(x: Tensor) -> Tensor:
    """Wrap an angle to ``[-pi, pi]``.

    Parameters
    ----------
    x : Tensor of shape (...)
        Angle [rad].

    Returns
    -------
    Tensor of shape (...)
        The same direction, in ``[-pi, pi]`` [rad].
    """
    return x - torch.round(x * (0.5 / math.pi)) * (2.0 * math.pi)


def sinc(x: Tensor, sin_x: Tensor | None = None) -> Tensor:
    """``sin(x) / x``, equal to 1 at 0, bit-reproducible.

    Parameters
    ----------
    x : Tensor of shape (...)
        Angle [rad].
    sin_x : Tensor of shape (...) or None
        ``sin(x)`` when the caller already has it.

    Returns
    -------
    Tensor of shape (...)
    """
    z = x * x
    # Taylor series to z^5 below |x| = 1 (error < 2e-10), the quotient above.
    taylor = (
        (
            ((-1.0 / 39916800.0 * z + 1.0 / 362880.0) * z - 1.0 / 5040.0) * z
            + 1.0 / 120.0
        )
        * z
        - 1.0 / 6.0
    ) * z + 1.0
    small = torch.abs(x) < 1.0
    if sin_x is None:
        sin_x, _ = sincos(x)
    return torch.where(small, taylor, sin_x / torch.where(small, 1.0, x))


_SQRT_HALF = 0.707106781186547524
_L = (
    7.0376836292e-2,
    -1.1514610310e-1,
    1.1676998740e-1,
    -1.2420140846e-1,
    1.4249322787e-1,
    -1.6668057665e-1,
    2.0000714765e-1,
    -2.4999993993e-1,
    3.3333331174e-1,
)


def log(x: Tensor) -> Tensor:
    """Natural logarithm of positive finite ``x``, bit-reproducible.

    Parameters
    ----------
    x : Tensor of shape (...)
        Positive, finite.

    Returns
    -------
    Tensor of shape (...)
    """
    m, e = torch.frexp(x)  # x = m 2**e, m in [0.5, 1)
    small = m < _SQRT_HALF
    e = torch.where(small, e - 1, e).to(x.dtype)
    f = torch.where(small, m + m - 1.0, m - 1.0)
    z = f * f
    p = f * 0.0 + _L[0]
    for coef in _L[1:]:
        p = p * f + coef
    y = p * f * z
    y = y + e * -2.12194440e-4
    y = y - 0.5 * z
    return (f + y) + e * 0.693359375
