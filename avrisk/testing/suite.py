"""A suite of rare-event problems with exact answers, for benchmarks (issue 46).

Each problem is an :class:`~avrisk.testing.problems.AnalyticProblem`: a base
``P0`` (an engine family), a batched ``f`` of shape ``(n, D) -> (n,)``, a
threshold ``gamma`` and ``p = P0(f(X) <= gamma)`` computed independently of
``f`` (``reference`` says how; ``p_rel_error`` is the reference's own relative
standard error, 0 for closed forms and quadratures). The families aim at the
shapes a user's scenario has and the bundled ones do not:

* :func:`k_region_problem` -- ``k`` half-space failure regions of unequal mass
  with orthogonal normals in ``d`` dimensions (several mechanisms, one rare).
* :func:`plateau_problem` -- ``f`` constant (a tie) on 90% to 99.99% of ``P0``
  and continuous elsewhere, as a capped time-to-collision is when nothing
  closes.
* :func:`beta_product_problem`, :func:`beta_pair_product_problem` and
  :func:`~avrisk.testing.problems.beta_sum_problem` -- blocks of the engine's
  :class:`~avrisk.rare.ScaledBeta` family.
* :func:`reliability_problem` -- the structural-reliability problems of the
  ``otbenchmark`` package (OpenTURNS), mapped to standard-normal space by
  their input distributions' iso-probabilistic transforms: the problem is
  ``u ~ N(0, I_D)``, ``f(u) = g(T^-1(u))``, ``gamma = 0``.

Credit and licence: the reliability problems are those collected in the
"Reliability problems" repository of Rozsas and Slobbe (TNO, 2019) and
packaged by ``otbenchmark`` (Baudin, Fekhari and others, LGPL-3.0). Their
limit-state formulas and input distributions are re-implemented here from the
published definitions (no code of ``otbenchmark`` is copied); ``otbenchmark``
itself pins ``numpy<2`` and so is not a dependency. Its listed reference
probabilities are not used: each reference here is computed afresh (closed
form, one-dimensional quadrature, or conditional Monte Carlo), and several
differ from the listed ones by 0.75% to 6.7%.

:func:`suite_problem` builds any problem by name (a generated family takes
its parameters from the name, e.g. ``kregions_k5_d50_p1e-06``), and
:data:`SUITE` lists the names the benchmark runs by default
(``benchmarks/exact_suite.py``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np
from scipy import integrate, optimize, special, stats

from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.rare.families.base import FloatArray
from avrisk.testing.problems import (
    AnalyticProblem,
    beta_sum_problem,
    four_branch_problem,
)

__all__ = [
    "CONDITIONAL_MC",
    "RELIABILITY_PROBLEMS",
    "SUITE",
    "beta_pair_product_problem",
    "beta_product_problem",
    "conditional_mc_reference",
    "k_region_problem",
    "plateau_problem",
    "reliability_problem",
    "suite_problem",
]

#: Seed of the orthonormal directions of the generated families: part of the
#: problem's definition, not of a run.
DIRECTIONS_SEED = 46


def _quad(fn: Callable[[float], float], lo: float, hi: float, points=None) -> float:
    """Adaptive quadrature to near machine precision (relative 1e-12)."""
    value, _ = integrate.quad(
        fn, lo, hi, epsabs=0.0, epsrel=1e-12, limit=500, points=points
    )
    return float(value)


def _directions(dim: int, k: int) -> FloatArray:
    """``k`` orthonormal directions in ``R^dim``, shape (k, dim), fixed by the seed."""
    if k > dim:
        raise ValueError(f"{k} orthogonal directions need dim >= {k}; got {dim}")
    rng = np.random.default_rng(DIRECTIONS_SEED)
    q, _ = np.linalg.qr(rng.standard_normal((dim, k)))
    return q.T.copy()


def _standard_normal(dim: int) -> FixedCovNormal:
    return FixedCovNormal(np.zeros(dim), cov=np.eye(dim))


def _union(p_i: np.ndarray) -> float:
    """``1 - prod(1 - p_i)`` without cancellation."""
    return float(-np.expm1(np.sum(np.log1p(-p_i))))


# --------------------------------------------------------------------------
# Generated families


def k_region_problem(
    k: int, dim: int, p: float = 1e-6, ratio: float = 0.5
) -> AnalyticProblem:
    """``k`` half-space failure regions of unequal mass in ``N(0, I_dim)``.

    Region ``i`` is ``{a_i . x >= beta_i}`` with orthonormal ``a_1..a_k``
    (shape (k, dim), a fixed random rotation, so no method gains from the
    coordinate axes), and ``f(x) = min_i (beta_i - a_i . x)``, ``gamma = 0``.
    The regions' masses ``p_i = Phi(-beta_i)`` fall geometrically,
    ``p_i proportional to ratio^(i-1)``, scaled so that the union has
    probability ``p``; the regions are independent events (orthogonal
    normals), so exactly

        p = 1 - prod_i (1 - Phi(-beta_i)).

    Parameters
    ----------
    k : int
        Number of regions, ``1 <= k <= dim``.
    dim : int
        Dimension ``d``.
    p : float
        Target probability of the union (``p_exact`` is the closed form at the
        solved ``beta_i``, equal to ``p`` to solver precision).
    ratio : float
        Mass of region ``i + 1`` over that of region ``i``, in (0, 1].
    """
    if not (1 <= k <= dim and 0.0 < p < 1.0 and 0.0 < ratio <= 1.0):
        raise ValueError(f"need 1 <= k <= dim, 0 < p < 1, 0 < ratio <= 1; got {k}")
    shares = ratio ** np.arange(k)
    shares = shares / shares.sum()
    scale = optimize.brentq(
        lambda s: _union(np.minimum(s * shares, 1 - 1e-16)) - p,
        p / 10,
        1.0 / shares.max(),
        xtol=1e-300,
        rtol=1e-15,
    )
    betas = stats.norm.isf(scale * shares)
    normals = _directions(dim, k)

    def f(x: FloatArray) -> FloatArray:
        return np.min(betas[None, :] - x @ normals.T, axis=1)

    p_exact = _union(stats.norm.sf(betas))
    return AnalyticProblem(
        f"kregions_k{k}_d{dim}_p{p:.0e}",
        _standard_normal(dim),
        f,
        0.0,
        p_exact,
        reference=f"closed form, 1 - prod(1 - Phi(-beta_i)), beta = "
        f"{', '.join(f'{b:.4f}' for b in betas)}",
    )


#: The value of ``f`` on the plateau (a capped time-to-collision's cap).
PLATEAU_CAP = 1.0


def plateau_problem(
    share: float, p: float = 1e-6, dim: int = 10, kind: str = "self"
) -> AnalyticProblem:
    """``f`` ties at ``PLATEAU_CAP`` on a share of ``P0``; continuous elsewhere.

    ``X ~ N(0, I_dim)``, ``a`` and ``b`` orthonormal (a fixed rotation),
    ``gamma = 0``.

    * ``kind="self"``: ``f = min(CAP, beta - a . x)``. The plateau is
      ``a . x <= beta - CAP``, of mass exactly ``share`` (``CAP = beta -
      Phi^-1(share)``); ``p = Phi(-beta)``.
    * ``kind="gate"``: the plateau is set by another coordinate, as when the
      other car does not close in: ``f = CAP`` where ``b . x < c`` and
      ``min(CAP, beta - a . x)`` elsewhere, with ``Phi(c) = share``. Then
      ``p = (1 - share) Phi(-beta)`` and the plateau's mass is ``share + (1 -
      share) Phi(beta - CAP)`` (a little more than ``share``).

    Parameters
    ----------
    share : float
        In (0, 1): the share of ``P0`` where ``f`` ties (``kind="self"``), or
        where the gate is shut (``kind="gate"``).
    p : float
        The event's probability; for ``"gate"`` below ``1 - share``.
    dim : int
        Dimension, at least 2.
    kind : {"self", "gate"}
    """
    if not (0.0 < share < 1.0 and dim >= 2):
        raise ValueError(f"need 0 < share < 1 and dim >= 2; got {share}, {dim}")
    a, b = _directions(dim, 2)
    cap = PLATEAU_CAP
    if kind == "self":
        beta = float(stats.norm.isf(p))
        cap = beta - float(stats.norm.ppf(share))
        if cap <= 0:
            raise ValueError(f"share={share} leaves no plateau above p={p}")

        def f(x: FloatArray) -> FloatArray:
            return np.minimum(cap, beta - x @ a)

        p_exact = float(stats.norm.sf(beta))
        mass = share
    elif kind == "gate":
        if not p < 1.0 - share:
            raise ValueError(f"p={p} must be below 1 - share = {1 - share}")
        c = float(stats.norm.ppf(share))
        beta = float(stats.norm.isf(p / (1.0 - share)))

        def f(x: FloatArray) -> FloatArray:
            open_ = x @ b >= c
            return np.where(open_, np.minimum(cap, beta - x @ a), cap)

        p_exact = float(stats.norm.sf(c) * stats.norm.sf(beta))
        mass = share + (1.0 - share) * float(stats.norm.cdf(beta - cap))
    else:
        raise ValueError(f"kind must be 'self' or 'gate'; got {kind!r}")
    return AnalyticProblem(
        f"plateau_{kind}_m{share:g}_d{dim}_p{p:.0e}",
        _standard_normal(dim),
        f,
        0.0,
        p_exact,
        reference=f"closed form; f ties at {cap:.4g} on {mass:.6g} of P0",
    )


def beta_product_problem(
    k: int = 4, p: float = 1e-6, a: float = 2.0
) -> AnalyticProblem:
    """The product of ``k`` i.i.d. ``Beta(a, 1)`` below a threshold ``t``.

    Each block is the engine's ``ScaledBeta(a, 1)`` on ``[0, 1]``. Since
    ``-log U ~ Exponential(a)`` for ``U ~ Beta(a, 1)``, ``-log prod U_i ~
    Gamma(k, rate a)`` and

        p = P(prod U_i <= t) = Gamma(k, a).sf(-log t),

    closed form; ``t`` is solved so that ``p`` is the target. ``f(x) = sum_i
    log x_i``, ``gamma = log t`` (the log of the product, so that ``f`` keeps
    its precision near 0).
    """
    log_t = -float(stats.gamma.isf(p, k, scale=1.0 / a))
    base = Product([ScaledBeta(a, 1.0, bounds=(0.5, 7.0)) for _ in range(k)])

    def f(x: FloatArray) -> FloatArray:
        with np.errstate(divide="ignore"):
            return np.log(x).sum(axis=1)

    p_exact = float(stats.gamma.sf(-log_t, k, scale=1.0 / a))
    return AnalyticProblem(
        f"beta_product_k{k}_p{p:.0e}",
        base,
        f,
        log_t,
        p_exact,
        reference="closed form, the Gamma(k, a) tail of -log of the product",
    )


def _beta22_cdf(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def beta_pair_product_problem(p: float = 1e-6) -> AnalyticProblem:
    """Two ``Beta(2, 2)`` (``ScaledBeta`` on ``[0, 1]``) with product below ``t``.

    With ``F(x) = 3 x^2 - 2 x^3`` the ``Beta(2, 2)`` distribution function,

        p = P(U_1 U_2 <= t) = int_0^1 6 u (1 - u) F(min(1, t / u)) du,

    by quadrature split at ``u = t`` (relative error about 1e-12); ``t`` is
    solved so that ``p`` is the target. ``f(x) = x_1 x_2``, ``gamma = t``.
    """

    def cdf(t: float) -> float:
        head = _beta22_cdf(t)  # u <= t: F(t/u) = 1
        tail = _quad(lambda u: 6 * u * (1 - u) * _beta22_cdf(t / u), t, 1.0)
        return head + tail

    t = float(
        optimize.brentq(
            lambda s: math.log(cdf(s)) - math.log(p),
            1e-12,
            0.5,
            xtol=1e-300,
            rtol=1e-14,
        )
    )
    base = Product([ScaledBeta(2.0, 2.0) for _ in range(2)])

    def f(x: FloatArray) -> FloatArray:
        return x[:, 0] * x[:, 1]

    return AnalyticProblem(
        f"beta_pair_product_p{p:.0e}",
        base,
        f,
        t,
        cdf(t),
        reference="quadrature of the Beta(2, 2) distribution function",
    )


# --------------------------------------------------------------------------
# otbenchmark's reliability problems, in standard-normal space


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

_sf, _cdf, _pdf = stats.norm.sf, stats.norm.cdf, stats.norm.pdf
_INF = np.inf


def _p_rp22() -> float:
    # u = (x1 + x2)/sqrt2, v = (x1 - x2)/sqrt2 independent: u >= 2.5 + 0.2 v^2
    return _quad(lambda v: _pdf(v) * _sf(2.5 + 0.2 * v * v), -_INF, _INF)


def _p_rp24() -> float:
    # x = 10 + 3 u; v, w the rotated standard normals: v >= 2.5 + c w^4 with
    # 0.2357 * 3 sqrt2 = 1.00000 (to 5 digits, kept exact here) on v
    a = 0.2357 * 3 * math.sqrt(2)
    c = 0.00463 * (3 * math.sqrt(2)) ** 4
    return _quad(lambda w: _pdf(w) * _sf((2.5 + c * w**4) / a), -_INF, _INF)


def _p_rp25() -> float:
    # (x1^2 + 16)/8 <= x2 <= 16 x1 - 32, non-empty for x1 in [64 - sqrt(3824), ..]
    lo = 64 - math.sqrt(64**2 - 272)

    def inner(x1: float) -> float:
        return _pdf(x1) * max(0.0, _sf((x1 * x1 + 16) / 8) - _sf(16 * x1 - 32))

    return _quad(inner, lo, 40.0)


def _p_rp28() -> float:
    mu1, s1, mu2, s2, t = 78_064.0, 11_710.0, 0.0104, 0.00156, 146.14
    u0 = -mu2 / s2  # x2 = 0

    def positive(u: float) -> float:  # x2 > 0: x1 <= t / x2
        return _pdf(u) * _cdf((t / (mu2 + s2 * u) - mu1) / s1)

    def negative(u: float) -> float:  # x2 < 0: x1 >= t / x2
        return _pdf(u) * _sf((t / (mu2 + s2 * u) - mu1) / s1)

    return _quad(negative, -_INF, u0) + _quad(positive, u0, _INF, points=None)


def _p_rp31() -> float:
    return _quad(lambda x: _pdf(x) * _sf(2 + 256 * x**4), -_INF, _INF)


def _p_rp33() -> float:
    # x3 >= 3, or x3 < 3 and x1 + x2 >= 3 sqrt3 - x3 (x1 + x2 ~ N(0, 2))
    r3 = 3 * math.sqrt(3)
    inside = _quad(lambda z: _pdf(z) * _sf((r3 - z) / math.sqrt(2)), -_INF, 3.0)
    return float(_sf(3.0)) + inside


def _p_rp35() -> float:
    def a(x1: float) -> float:
        return 2 + math.exp(-0.1 * x1 * x1) + (0.2 * x1) ** 4

    def negative(x1: float) -> float:  # x2 >= a or x2 <= 4.5 / x1 (< 0 < a)
        return _pdf(x1) * (_sf(a(x1)) + _cdf(4.5 / x1))

    def positive(x1: float) -> float:  # x2 >= min(a, 4.5 / x1)
        return _pdf(x1) * _sf(min(a(x1), 4.5 / x1))

    return _quad(negative, -_INF, 0.0) + _quad(positive, 0.0, _INF)


def _p_rp53() -> float:
    def inner(z: float) -> float:
        x1 = 1.5 + z
        edge = 1 + 20 * (math.sin(2.5 * x1) + 2) / (x1 * x1 + 4)
        return _pdf(z) * _sf(edge - 2.5)

    return _quad(inner, -12.0, 12.0, points=np.linspace(-6, 6, 25))


def _p_rp54() -> float:
    return float(stats.gamma.cdf(8.951, 20))


def _p_rp57() -> float:
    # region A: (2 - x1)/8 <= x2 <= cbrt(x1^2 - 3); disk D: |x - (-3, -3)| <= 2.
    # D lies in x2 <= -1 < (2 - x1)/8 for x1 in [-5, -1]: disjoint from A.
    def inner(x1: float) -> float:
        lo, hi = (2 - x1) / 8, float(np.cbrt(x1 * x1 - 3))
        return _pdf(x1) * max(0.0, _cdf(hi) - _cdf(lo)) if hi > lo else 0.0

    area = _quad(inner, -12.0, 12.0, points=[-2.0, -1.7, 0.0, 1.7, 2.0])
    disk = float(stats.ncx2.cdf(4.0, 2, 18.0))
    return area + disk


def _p_rp63() -> float:
    # x1 >= 0.1 C - 4.5 with C ~ chi2(99)
    return _quad(
        lambda c: stats.chi2.pdf(c, 99) * _sf(0.1 * c - 4.5),
        0.0,
        _INF,
        points=None,
    )


def _p_rp75() -> float:
    return 2 * _quad(lambda x: _pdf(x) * _sf(3.0 / x), 0.0, _INF)


def _p_rp77() -> float:
    low = _quad(lambda x3: _pdf(x3 - 4) * _cdf((x3 - 10) / math.sqrt(1.25)), -_INF, 5.0)
    high = _quad(lambda x3: _pdf(x3 - 4) * _sf(x3), 5.0, _INF)
    return low + high


def _p_rp89() -> float:
    return _quad(
        lambda x: _pdf(x) * _sf(min(8 - x * x, 6 - x / 5)),
        -_INF,
        _INF,
        points=None,
    )


def _p_rp111() -> float:
    return 4 * _quad(lambda x: _pdf(x) * _sf(12.5 / x), 0.0, _INF)


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


#: name -> (dimension, limit state g(u), reference p or None, how it was got).
RELIABILITY_PROBLEMS: dict[
    str, tuple[int, Callable[[FloatArray], FloatArray], Callable[[], float], str]
] = {
    "RP8": (6, _g_rp8, lambda: _CONDITIONAL_REFERENCES["RP8"][0], "cmc"),
    "RP14": (5, _g_rp14, lambda: _CONDITIONAL_REFERENCES["RP14"][0], "cmc"),
    "RP22": (2, _g_rp22, _p_rp22, "quadrature over the rotated coordinate"),
    "RP24": (2, _g_rp24, _p_rp24, "quadrature over the rotated coordinate"),
    "RP25": (2, _g_rp25, _p_rp25, "quadrature over x1"),
    "RP28": (2, _g_rp28, _p_rp28, "quadrature over x2"),
    "RP31": (2, _g_rp31, _p_rp31, "quadrature over x1"),
    "RP33": (3, _g_rp33, _p_rp33, "quadrature over x3"),
    "RP35": (2, _g_rp35, _p_rp35, "quadrature over x1"),
    "RP38": (7, _g_rp38, lambda: _CONDITIONAL_REFERENCES["RP38"][0], "cmc"),
    "RP53": (2, _g_rp53, _p_rp53, "quadrature over x1"),
    "RP54": (20, _g_rp54, _p_rp54, "closed form, the Gamma(20, 1) distribution"),
    "RP57": (2, _g_rp57, _p_rp57, "quadrature over x1 plus a noncentral chi2"),
    "RP60": (5, _g_rp60, lambda: _CONDITIONAL_REFERENCES["RP60"][0], "cmc"),
    "RP63": (100, _g_rp63, _p_rp63, "quadrature over the chi2(99) of x2..x100"),
    "RP75": (2, _g_rp75, _p_rp75, "quadrature over x1"),
    "RP77": (3, _g_rp77, _p_rp77, "quadrature over x3"),
    "RP89": (2, _g_rp89, _p_rp89, "quadrature over x1"),
    "RP91": (5, _g_rp91, lambda: _CONDITIONAL_REFERENCES["RP91"][0], "cmc"),
    "RP107": (10, _g_rp107, lambda: float(_sf(5.0)), "closed form, Phi(-5)"),
    "RP110": (
        2,
        _g_rp110,
        lambda: _union(_sf(np.array([4.0, 5.0]))),
        "closed form, 1 - (1 - Phi(-4))(1 - Phi(-5))",
    ),
    "RP111": (2, _g_rp111, _p_rp111, "quadrature over x1"),
}


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
            name, _standard_normal(dim), g, 0.0, p, reference=how, p_rel_error=rel
        )
    return AnalyticProblem(name, _standard_normal(dim), g, 0.0, reference(), how)


# --------------------------------------------------------------------------
# By name

_PATTERNS: list[tuple[str, Callable[..., AnalyticProblem]]] = [
    (
        r"kregions_k(?P<k>\d+)_d(?P<dim>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, dim, p: k_region_problem(int(k), int(dim), float(p)),
    ),
    (
        r"plateau_(?P<kind>self|gate)_m(?P<share>[0-9.]+)_d(?P<dim>\d+)"
        r"_p(?P<p>[0-9.e+-]+)",
        lambda kind, share, dim, p: plateau_problem(
            float(share), float(p), int(dim), kind
        ),
    ),
    (
        r"beta_product_k(?P<k>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, p: beta_product_problem(int(k), float(p)),
    ),
    (
        r"beta_pair_product_p(?P<p>[0-9.e+-]+)",
        lambda p: beta_pair_product_problem(float(p)),
    ),
    (
        r"beta_sum_k(?P<k>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, p: _beta_sum(int(k), float(p)),
    ),
]


def _beta_sum(k: int, p: float) -> AnalyticProblem:
    problem = beta_sum_problem(k, p)
    return AnalyticProblem(
        f"beta_sum_k{k}_p{p:.0e}",
        problem.base,
        problem.f,
        problem.gamma,
        problem.p_exact,
        reference="closed form over the simplex (beta_sum_cdf)",
    )


def suite_problem(name: str) -> AnalyticProblem:
    """The problem called ``name`` (a :data:`SUITE` name or a family's pattern).

    Raises
    ------
    KeyError
        If no problem or family matches (the message lists the patterns).
    """
    if name in RELIABILITY_PROBLEMS or name == "four-branch":
        return reliability_problem(name)
    for pattern, build in _PATTERNS:
        match = re.fullmatch(pattern, name)
        if match:
            return build(**match.groupdict())
    raise KeyError(
        f"no problem {name!r}: one of {sorted(RELIABILITY_PROBLEMS)}, four-branch, "
        f"or a family: {', '.join(p for p, _ in _PATTERNS)}"
    )


#: The problems the benchmark runs by default: a few points of each family
#: and every reliability problem that is rare (RP55, p = 0.56, is left out).
SUITE: tuple[str, ...] = (
    "kregions_k1_d2_p1e-03",
    "kregions_k2_d20_p1e-05",
    "kregions_k2_d100_p1e-08",
    "kregions_k5_d50_p1e-06",
    "kregions_k10_d200_p1e-09",
    "kregions_k3_d1000_p1e-06",
    "plateau_self_m0.9_d10_p1e-06",
    "plateau_self_m0.99_d10_p1e-06",
    "plateau_self_m0.9999_d10_p1e-06",
    "plateau_gate_m0.9999_d10_p1e-06",
    "beta_sum_k6_p1e-06",
    "beta_product_k4_p1e-06",
    "beta_pair_product_p1e-06",
    *RELIABILITY_PROBLEMS,
    "four-branch",
)
