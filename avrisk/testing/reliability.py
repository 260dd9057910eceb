"""The ``otbenchmark`` reliability problems with their exact references.

A problem is ``u ~ N(0, I_D)``, ``f(u) = g(T^-1(u))`` with ``g`` its limit
state (:mod:`avrisk.testing.limit_states`), ``gamma = 0``. Each reference is
computed afresh, never taken from ``otbenchmark``'s list: a closed form, a
one-dimensional quadrature, or conditional Monte Carlo with its relative
standard error (:func:`conditional_mc_reference`, recorded in
``_CONDITIONAL_REFERENCES``). Credit and licence: :mod:`avrisk.testing.suite`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import stats

from avrisk.rare.families.base import FloatArray
from avrisk.testing.exact import quad, standard_normal, union_probability
from avrisk.testing.limit_states import CONDITIONAL_MC, LIMIT_STATES
from avrisk.testing.problems import AnalyticProblem, four_branch_problem

__all__ = [
    "RELIABILITY_PROBLEMS",
    "conditional_mc_reference",
    "reliability_problem",
]


_sf, _cdf, _pdf = stats.norm.sf, stats.norm.cdf, stats.norm.pdf
_INF = np.inf


def _p_rp22() -> float:
    # u = (x1 + x2)/sqrt2, v = (x1 - x2)/sqrt2 independent: u >= 2.5 + 0.2 v^2
    return quad(lambda v: _pdf(v) * _sf(2.5 + 0.2 * v * v), -_INF, _INF)


def _p_rp24() -> float:
    # x = 10 + 3 u; v, w the rotated standard normals: v >= 2.5 + c w^4 with
    # 0.2357 * 3 sqrt2 = 1.00000 (to 5 digits, kept exact here) on v
    a = 0.2357 * 3 * math.sqrt(2)
    c = 0.00463 * (3 * math.sqrt(2)) ** 4
    return quad(lambda w: _pdf(w) * _sf((2.5 + c * w**4) / a), -_INF, _INF)


def _p_rp25() -> float:
    # (x1^2 + 16)/8 <= x2 <= 16 x1 - 32, non-empty for x1 in [64 - sqrt(3824), ..]
    lo = 64 - math.sqrt(64**2 - 272)

    def inner(x1: float) -> float:
        return _pdf(x1) * max(0.0, _sf((x1 * x1 + 16) / 8) - _sf(16 * x1 - 32))

    return quad(inner, lo, 40.0)


def _p_rp28() -> float:
    mu1, s1, mu2, s2, t = 78_064.0, 11_710.0, 0.0104, 0.00156, 146.14
    u0 = -mu2 / s2  # x2 = 0

    def positive(u: float) -> float:  # x2 > 0: x1 <= t / x2
        return _pdf(u) * _cdf((t / (mu2 + s2 * u) - mu1) / s1)

    def negative(u: float) -> float:  # x2 < 0: x1 >= t / x2
        return _pdf(u) * _sf((t / (mu2 + s2 * u) - mu1) / s1)

    return quad(negative, -_INF, u0) + quad(positive, u0, _INF, points=None)


def _p_rp31() -> float:
    return quad(lambda x: _pdf(x) * _sf(2 + 256 * x**4), -_INF, _INF)


def _p_rp33() -> float:
    # x3 >= 3, or x3 < 3 and x1 + x2 >= 3 sqrt3 - x3 (x1 + x2 ~ N(0, 2))
    r3 = 3 * math.sqrt(3)
    inside = quad(lambda z: _pdf(z) * _sf((r3 - z) / math.sqrt(2)), -_INF, 3.0)
    return float(_sf(3.0)) + inside


def _p_rp35() -> float:
    def a(x1: float) -> float:
        return 2 + math.exp(-0.1 * x1 * x1) + (0.2 * x1) ** 4

    def negative(x1: float) -> float:  # x2 >= a or x2 <= 4.5 / x1 (< 0 < a)
        return _pdf(x1) * (_sf(a(x1)) + _cdf(4.5 / x1))

    def positive(x1: float) -> float:  # x2 >= min(a, 4.5 / x1)
        return _pdf(x1) * _sf(min(a(x1), 4.5 / x1))

    return quad(negative, -_INF, 0.0) + quad(positive, 0.0, _INF)


def _p_rp53() -> float:
    def inner(z: float) -> float:
        x1 = 1.5 + z
        edge = 1 + 20 * (math.sin(2.5 * x1) + 2) / (x1 * x1 + 4)
        return _pdf(z) * _sf(edge - 2.5)

    return quad(inner, -12.0, 12.0, points=np.linspace(-6, 6, 25))


def _p_rp54() -> float:
    return float(stats.gamma.cdf(8.951, 20))


def _p_rp57() -> float:
    # region A: (2 - x1)/8 <= x2 <= cbrt(x1^2 - 3); disk D: |x - (-3, -3)| <= 2.
    # D lies in x2 <= -1 < (2 - x1)/8 for x1 in [-5, -1]: disjoint from A.
    def inner(x1: float) -> float:
        lo, hi = (2 - x1) / 8, float(np.cbrt(x1 * x1 - 3))
        return _pdf(x1) * max(0.0, _cdf(hi) - _cdf(lo)) if hi > lo else 0.0

    area = quad(inner, -12.0, 12.0, points=[-2.0, -1.7, 0.0, 1.7, 2.0])
    disk = float(stats.ncx2.cdf(4.0, 2, 18.0))
    return area + disk


def _p_rp63() -> float:
    # x1 >= 0.1 C - 4.5 with C ~ chi2(99)
    return quad(
        lambda c: stats.chi2.pdf(c, 99) * _sf(0.1 * c - 4.5),
        0.0,
        _INF,
        points=None,
    )


def _p_rp75() -> float:
    return 2 * quad(lambda x: _pdf(x) * _sf(3.0 / x), 0.0, _INF)


def _p_rp77() -> float:
    low = quad(lambda x3: _pdf(x3 - 4) * _cdf((x3 - 10) / math.sqrt(1.25)), -_INF, 5.0)
    high = quad(lambda x3: _pdf(x3 - 4) * _sf(x3), 5.0, _INF)
    return low + high


def _p_rp89() -> float:
    return quad(
        lambda x: _pdf(x) * _sf(min(8 - x * x, 6 - x / 5)),
        -_INF,
        _INF,
        points=None,
    )


def _p_rp111() -> float:
    return 4 * quad(lambda x: _pdf(x) * _sf(12.5 / x), 0.0, _INF)


#: Conditional Monte Carlo references: name -> (p, relative standard error),
#: from :func:`conditional_mc_reference` with ``n = 10**8`` and ``seed = 0``.
_CONDITIONAL_REFERENCES: dict[str, tuple[float, float]] = {
    "RP8": (7.925524960840667e-04, 3.14e-03),
    "RP14": (7.73521343188575e-04, 2.69e-03),
    "RP38": (8.05932528721223e-03, 9.2e-04),
    "RP60": (4.481206431965096e-02, 3.84e-04),
    "RP91": (7.002216479625142e-04, 4.71e-05),
}


def conditional_mc_reference(
    name: str, n: int, seed: int = 0, chunk: int = 1_000_000
) -> tuple[float, float]:
    """A conditional Monte Carlo estimate of a reliability problem's ``p``.

    One input (a resistance the limit state is monotone in) is integrated in
    closed form given the others, and the others are sampled:
    ``p = E[P(failure | u_rest)]``.

    Returns
    -------
    p : float
    rel_se : float
        Its relative standard error.
    """
    dim, conditional = CONDITIONAL_MC[name]
    rng = np.random.default_rng(seed)
    total, total_sq, done = 0.0, 0.0, 0
    while done < n:
        m = min(chunk, n - done)
        c = conditional(rng.standard_normal((m, dim)))
        total += float(c.sum())
        total_sq += float((c * c).sum())
        done += m
    mean = total / n
    var = max(total_sq / n - mean * mean, 0.0)
    return mean, math.sqrt(var / n) / mean


#: name -> how its reference ``p`` is computed, and how that is described.
_REFERENCES: dict[str, tuple[Callable[[], float], str]] = {
    "RP8": (lambda: _CONDITIONAL_REFERENCES["RP8"][0], "cmc"),
    "RP14": (lambda: _CONDITIONAL_REFERENCES["RP14"][0], "cmc"),
    "RP22": (_p_rp22, "quadrature over the rotated coordinate"),
    "RP24": (_p_rp24, "quadrature over the rotated coordinate"),
    "RP25": (_p_rp25, "quadrature over x1"),
    "RP28": (_p_rp28, "quadrature over x2"),
    "RP31": (_p_rp31, "quadrature over x1"),
    "RP33": (_p_rp33, "quadrature over x3"),
    "RP35": (_p_rp35, "quadrature over x1"),
    "RP38": (lambda: _CONDITIONAL_REFERENCES["RP38"][0], "cmc"),
    "RP53": (_p_rp53, "quadrature over x1"),
    "RP54": (_p_rp54, "closed form, the Gamma(20, 1) distribution"),
    "RP57": (_p_rp57, "quadrature over x1 plus a noncentral chi2"),
    "RP60": (lambda: _CONDITIONAL_REFERENCES["RP60"][0], "cmc"),
    "RP63": (_p_rp63, "quadrature over the chi2(99) of x2..x100"),
    "RP75": (_p_rp75, "quadrature over x1"),
    "RP77": (_p_rp77, "quadrature over x3"),
    "RP89": (_p_rp89, "quadrature over x1"),
    "RP91": (lambda: _CONDITIONAL_REFERENCES["RP91"][0], "cmc"),
    "RP107": (lambda: float(_sf(5.0)), "closed form, Phi(-5)"),
    "RP110": (
        lambda: union_probability(_sf(np.array([4.0, 5.0]))),
        "closed form, 1 - (1 - Phi(-4))(1 - Phi(-5))",
    ),
    "RP111": (_p_rp111, "quadrature over x1"),
}

#: name -> (dimension, limit state g(u), reference p, how it was got).
RELIABILITY_PROBLEMS: dict[
    str, tuple[int, Callable[[FloatArray], FloatArray], Callable[[], float], str]
] = {name: (*LIMIT_STATES[name], *how) for name, how in _REFERENCES.items()}


def reliability_problem(name: str) -> AnalyticProblem:
    """An ``otbenchmark`` reliability problem in standard-normal space.

    ``u ~ N(0, I_D)``, ``f(u) = g(T^-1(u))`` with ``T`` the inputs'
    iso-probabilistic transform (each input independent: ``x_i =
    F_i^-1(Phi(u_i))``), ``gamma = 0``; the limit states and distributions are
    those of :data:`RELIABILITY_PROBLEMS` (the published definitions), and
    ``four-branch`` is :func:`~avrisk.testing.problems.four_branch_problem`.
    """
    if name == "four-branch":
        return four_branch_problem()
    dim, g, reference, how = RELIABILITY_PROBLEMS[name]
    if how == "cmc":
        p, rel = _CONDITIONAL_REFERENCES[name]
        how = f"conditional Monte Carlo, 1e8 samples, relative standard error {rel:.1e}"
        return AnalyticProblem(
            name, standard_normal(dim), g, 0.0, p, reference=how, p_rel_error=rel
        )
    return AnalyticProblem(name, standard_normal(dim), g, 0.0, reference(), how)
