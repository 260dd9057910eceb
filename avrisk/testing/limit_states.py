"""The ``otbenchmark`` reliability problems' limit states, in standard-normal space.

Each limit state takes standard normals ``u`` of shape ``(n, D)`` and returns
``g`` of shape ``(n,)``; failure is ``g <= 0``. The inputs are mapped from
``u`` by their iso-probabilistic transforms (each input independent: ``x_i =
F_i^-1(Phi(u_i))``), re-implemented from the published definitions (credit:
:mod:`avrisk.testing.suite`). For five of them the probability of failure
given all inputs but one is in closed form (:data:`CONDITIONAL_MC`), which
gives their references by conditional Monte Carlo
(:func:`avrisk.testing.reliability.conditional_mc_reference`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import special

from avrisk.rare.families.base import FloatArray

__all__ = ["CONDITIONAL_MC", "LIMIT_STATES"]


def _normal(u: FloatArray, mu: float, sigma: float) -> FloatArray:
    return mu + sigma * u


def _lognormal_params(mu: float, sigma: float) -> tuple[float, float]:
    """``(mean, sd)`` of ``log X``, ``X`` lognormal of mean ``mu`` and sd ``sigma``."""
    s = math.sqrt(math.log1p((sigma / mu) ** 2))
    return math.log(mu) - s * s / 2, s


def _lognormal(u: FloatArray, mu: float, sigma: float) -> FloatArray:
    m, s = _lognormal_params(mu, sigma)
    return np.exp(m + s * u)


def _uniform(u: FloatArray, a: float, b: float) -> FloatArray:
    return a + (b - a) * special.ndtr(u)


def _gumbel_max(u: FloatArray, mu: float, sigma: float) -> FloatArray:
    """Gumbel (maximum) of mean ``mu`` and sd ``sigma``, each tail kept precise."""
    scale = sigma * math.sqrt(6.0) / math.pi
    loc = mu - np.euler_gamma * scale
    return loc - scale * np.log(-special.log_ndtr(u))


def _exponential(u: FloatArray, rate: float) -> FloatArray:
    return -special.log_ndtr(-u) / rate


# Each limit state takes standard normals u of shape (n, D) and returns g of
# shape (n,); failure is g <= 0.


def _g_rp8(u: FloatArray) -> FloatArray:
    x = [_lognormal(u[:, i], 120.0, 12.0) for i in range(4)]
    x5 = _lognormal(u[:, 4], 50.0, 10.0)
    x6 = _lognormal(u[:, 5], 40.0, 8.0)
    return x[0] + 2 * x[1] + 2 * x[2] + x[3] - 5 * x5 - 5 * x6


def _g_rp14(u: FloatArray) -> FloatArray:
    x1 = _uniform(u[:, 0], 70.0, 80.0)
    return x1 - _rp14_load(u[:, 1:])


def _rp14_load(v: FloatArray) -> FloatArray:
    x2 = _normal(v[:, 0], 39.0, 0.1)
    x3 = _gumbel_max(v[:, 1], 1500.0, 350.0)
    x4 = _normal(v[:, 2], 400.0, 0.1)
    x5 = _normal(v[:, 3], 250_000.0, 35_000.0)
    return 32.0 / (np.pi * x2**3) * np.sqrt(x3**2 * x4**2 / 16.0 + x5**2)


def _g_rp22(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    return 2.5 - (x1 + x2) / math.sqrt(2) + 0.1 * (x1 - x2) ** 2


def _g_rp24(u: FloatArray) -> FloatArray:
    x1, x2 = _normal(u[:, 0], 10.0, 3.0), _normal(u[:, 1], 10.0, 3.0)
    return 2.5 - 0.2357 * (x1 - x2) + 0.00463 * (x1 + x2 - 20.0) ** 4


def _g_rp25(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    return np.maximum(x1**2 - 8 * x2 + 16, -16 * x1 + x2 + 32)


def _g_rp28(u: FloatArray) -> FloatArray:
    x1 = _normal(u[:, 0], 78_064.0, 11_710.0)
    x2 = _normal(u[:, 1], 0.0104, 0.00156)
    return x1 * x2 - 146.14


def _g_rp31(u: FloatArray) -> FloatArray:
    return 2.0 - u[:, 1] + 256.0 * u[:, 0] ** 4


def _g_rp33(u: FloatArray) -> FloatArray:
    return np.minimum(-u.sum(axis=1) + 3 * math.sqrt(3), -u[:, 2] + 3.0)


def _g_rp35(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    g1 = 2.0 - x2 + np.exp(-0.1 * x1**2) + (0.2 * x1) ** 4
    return np.minimum(g1, 4.5 - x1 * x2)


_RP38_MEANS = (350.0, 50.8, 3.81, 173.0, 9.38, 33.1, 0.036)


def _rp38_factor(v: FloatArray) -> FloatArray:
    """``g = 15.59e4 - x_1 * factor(x_2..x_7)``; ``v``: standard normals (n, 6)."""
    x2, x3, x4, x5, x6, x7 = (
        _normal(v[:, i], m, 0.1 * m) for i, m in enumerate(_RP38_MEANS[1:])
    )
    num = x4**2 - 4 * x5 * x6 * x7**2 + x4 * (x6 + 4 * x5 + 2 * x6 * x7)
    den = x4 * x5 * (x4 + x6 + 2 * x6 * x7)
    return x2**3 / (2 * x3**3) * num / den


def _g_rp38(u: FloatArray) -> FloatArray:
    x1 = _normal(u[:, 0], _RP38_MEANS[0], 0.1 * _RP38_MEANS[0])
    return 15.59e4 - x1 * _rp38_factor(u[:, 1:])


def _g_rp53(u: FloatArray) -> FloatArray:
    x1, x2 = _normal(u[:, 0], 1.5, 1.0), _normal(u[:, 1], 2.5, 1.0)
    return np.sin(5 * x1 / 2) + 2 - (x1**2 + 4) * (x2 - 1) / 20


def _g_rp54(u: FloatArray) -> FloatArray:
    return _exponential(u, 1.0).sum(axis=1) - 8.951


def _g_rp57(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    g1 = -(x1**2) + x2**3 + 3
    g2 = 2 - x1 - 8 * x2
    g3 = (x1 + 3) ** 2 + (x2 + 3) ** 2 - 4
    return np.minimum(np.maximum(g1, g2), g3)


_RP60_PARAMS = ((2200, 220), (2100, 210), (2300, 230), (2000, 200), (1200, 480))


def _rp60_system(v: FloatArray) -> FloatArray:
    """The part of RP60's ``g`` without ``x_1``; ``v``: standard normals (n, 4)."""
    x2, x3, x4, x5 = (_lognormal(v[:, i], *_RP60_PARAMS[i + 1]) for i in range(4))
    g10 = np.minimum.reduce([x2 - x5 / 2, x3 - x5 / 2, x4 - x5 / 2])
    g9 = np.maximum(x4 - x5, np.minimum(x2 - x5, x3 - x5))
    return np.maximum(g10, g9)


def _g_rp60(u: FloatArray) -> FloatArray:
    x1 = _lognormal(u[:, 0], *_RP60_PARAMS[0])
    x5 = _lognormal(u[:, 4], *_RP60_PARAMS[4])
    return np.minimum(x1 - x5, _rp60_system(u[:, 1:]))


def _g_rp63(u: FloatArray) -> FloatArray:
    return 0.1 * np.sum(u[:, 1:] ** 2, axis=1) - u[:, 0] - 4.5


def _g_rp75(u: FloatArray) -> FloatArray:
    return 3.0 - u[:, 0] * u[:, 1]


def _g_rp77(u: FloatArray) -> FloatArray:
    x1 = _normal(u[:, 0], 10.0, 0.5)
    x2 = u[:, 1]
    x3 = _normal(u[:, 2], 4.0, 1.0)
    return np.where(x3 <= 5.0, x1 - x2 - x3, x3 - x2)


def _g_rp89(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    return np.minimum(-(x1**2) - x2 + 8, -x1 / 5 - x2 + 6)


_RP91_PARAMS = ((0.07433, 0.005), (0.1, 0.01), (13.0, 60.0), (4751.0, 48.0))
_RP91_X5 = (-684.0, 11.0)


def _rp91_rest(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """RP91's ``g_1`` and the ``x_1`` below which ``g_2`` or ``g_3 <= 0``.

    ``v``: standard normals of ``x_2..x_5``, shape (n, 4).
    """
    x2, x3, x4 = (_normal(v[:, i], *_RP91_PARAMS[i + 1]) for i in range(3))
    x5 = _normal(v[:, 3], *_RP91_X5)
    g1 = (
        0.847
        + 0.96 * x2
        + 0.986 * x3
        - 0.216 * x4
        + 0.077 * x2**2
        + 0.11 * x3**2
        + (7 / 378) * x4**2
        - x3 * x2
        - 0.106 * x2 * x4
        - 0.11 * x3 * x4
    )
    root = np.sqrt(x3**2 + x4**2 - x3 * x4 + 3 * x5**2)
    return g1, np.maximum(root, np.abs(x4)) / 84_000.0


def _g_rp91(u: FloatArray) -> FloatArray:
    x1 = _normal(u[:, 0], *_RP91_PARAMS[0])
    x3 = _normal(u[:, 2], *_RP91_PARAMS[2])
    x4 = _normal(u[:, 3], *_RP91_PARAMS[3])
    x5 = _normal(u[:, 4], *_RP91_X5)
    g1, _ = _rp91_rest(u[:, 1:])
    g2 = 84_000 * x1 / np.sqrt(x3**2 + x4**2 - x3 * x4 + 3 * x5**2) - 1
    g3 = 84_000 * x1 / np.abs(x4) - 1
    return np.minimum.reduce([g1, g2, g3])


def _g_rp107(u: FloatArray) -> FloatArray:
    return 5 * math.sqrt(10) - u.sum(axis=1)


def _g_rp110(u: FloatArray) -> FloatArray:
    x1, x2 = u[:, 0], u[:, 1]
    g1 = np.where(x1 <= 3.5, 0.85 - 0.1 * x1, 4 - x1)
    g2 = np.where(x2 <= 2.0, 2.3 - x2, 0.5 - 0.1 * x2)
    return np.minimum(g1, g2)


def _g_rp111(u: FloatArray) -> FloatArray:
    return 12.5 - np.abs(u[:, 0] * u[:, 1])


# References by quadrature (each a function of nothing, the value p).

# Conditional Monte Carlo: P(fail | all inputs but one) in closed form, averaged.


def _cond_rp8(u: FloatArray) -> FloatArray:
    x = [_lognormal(u[:, i], 120.0, 12.0) for i in range(1, 4)]
    x5 = _lognormal(u[:, 4], 50.0, 10.0)
    x6 = _lognormal(u[:, 5], 40.0, 8.0)
    edge = 5 * x5 + 5 * x6 - 2 * x[0] - 2 * x[1] - x[2]  # x1 <= edge
    m, s = _lognormal_params(120.0, 12.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(edge > 0, special.ndtr((np.log(edge) - m) / s), 0.0)


def _cond_rp14(u: FloatArray) -> FloatArray:
    return np.clip((_rp14_load(u[:, 1:]) - 70.0) / 10.0, 0.0, 1.0)


def _cond_rp38(u: FloatArray) -> FloatArray:
    k = _rp38_factor(u[:, 1:])
    edge = 15.59e4 / k  # x1 k >= alpha
    mu, sd = _RP38_MEANS[0], 0.1 * _RP38_MEANS[0]
    return np.where(
        k > 0, special.ndtr((mu - edge) / sd), special.ndtr((edge - mu) / sd)
    )


def _cond_rp60(u: FloatArray) -> FloatArray:
    x5 = _lognormal(u[:, 4], *_RP60_PARAMS[4])
    m, s = _lognormal_params(*_RP60_PARAMS[0])
    below = special.ndtr((np.log(x5) - m) / s)  # P(x1 <= x5)
    return np.where(_rp60_system(u[:, 1:]) <= 0, 1.0, below)


def _cond_rp91(u: FloatArray) -> FloatArray:
    g1, edge = _rp91_rest(u[:, 1:])
    mu, sd = _RP91_PARAMS[0]
    return np.where(g1 <= 0, 1.0, special.ndtr((edge - mu) / sd))


#: name -> (dimension, P(failure | u) as a function of u of shape (n, D)).
CONDITIONAL_MC: dict[str, tuple[int, Callable[[FloatArray], FloatArray]]] = {
    "RP8": (6, _cond_rp8),
    "RP14": (5, _cond_rp14),
    "RP38": (7, _cond_rp38),
    "RP60": (5, _cond_rp60),
    "RP91": (5, _cond_rp91),
}

#: name -> (dimension ``D``, limit state ``g(u)``).
LIMIT_STATES: dict[str, tuple[int, Callable[[FloatArray], FloatArray]]] = {
    "RP8": (6, _g_rp8),
    "RP14": (5, _g_rp14),
    "RP22": (2, _g_rp22),
    "RP24": (2, _g_rp24),
    "RP25": (2, _g_rp25),
    "RP28": (2, _g_rp28),
    "RP31": (2, _g_rp31),
    "RP33": (3, _g_rp33),
    "RP35": (2, _g_rp35),
    "RP38": (7, _g_rp38),
    "RP53": (2, _g_rp53),
    "RP54": (20, _g_rp54),
    "RP57": (2, _g_rp57),
    "RP60": (5, _g_rp60),
    "RP63": (100, _g_rp63),
    "RP75": (2, _g_rp75),
    "RP77": (3, _g_rp77),
    "RP89": (2, _g_rp89),
    "RP91": (5, _g_rp91),
    "RP107": (10, _g_rp107),
    "RP110": (2, _g_rp110),
    "RP111": (2, _g_rp111),
}
