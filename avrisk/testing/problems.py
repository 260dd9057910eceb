"""Rare-event problems whose probability is known exactly.

* :func:`gaussian_linear_problem` -- ``X ~ N(0, I_D)``, ``f(x) = beta - u^T x``
  with ``|u| = 1``: ``P(f <= 0) = Phi(-beta)``.
* :func:`beta_sum_problem` -- the sum of ``k`` i.i.d. ``lo + scale Beta(2, 2)``
  variables (the paper's longitudinal marginal, ``80 + 40 Beta(2,2)`` m) below a
  threshold; exact by :func:`beta_sum_cdf`.
* :func:`mixed_problem` -- a Beta block and a Normal block that must *both* be
  extreme: ``f = max(beta part, normal part)``, so ``p`` is the product of the
  two exact probabilities.
* :func:`four_branch_problem` -- the four-branch series system of structural
  reliability: a 2-d standard normal and four failure regions in different
  directions (a test of methods that follow one failure mode only).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb, factorial

import numpy as np
from scipy import integrate, optimize, stats

from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.problem import BatchFunction


@dataclass(frozen=True)
class AnalyticProblem:
    """A rare-event problem with its exact probability.

    Attributes
    ----------
    name : str
    base : ExponentialFamily
    f : callable
        ``(n, D) -> (n,)``.
    gamma : float
    p_exact : float
        ``P_base(f(X) <= gamma)``.
    reference : str
        How ``p_exact`` was computed (closed form, quadrature, conditional
        Monte Carlo), one phrase.
    p_rel_error : float
        Relative standard error of ``p_exact``: 0 for a closed form or a
        quadrature to near machine precision; a Monte Carlo reference's own.
    """

    name: str
    base: ExponentialFamily
    f: BatchFunction
    gamma: float
    p_exact: float
    reference: str = "closed form"
    p_rel_error: float = 0.0


def gaussian_linear_problem(dim: int, p: float = 1e-6) -> AnalyticProblem:
    """``N(0, I_dim)`` and a linear limit state at reliability index ``Phi^-1(1-p)``.

    The proposal family is the unconstrained-mean normal (the optimal mean shift
    lies about ``beta`` away from the base mean).
    """
    beta = float(stats.norm.isf(p))
    u = np.ones(dim) / np.sqrt(dim)

    def f(x: FloatArray) -> FloatArray:
        return beta - x @ u

    base = FixedCovNormal(np.zeros(dim), cov=np.eye(dim))
    return AnalyticProblem(
        f"gaussian_linear_d{dim}", base, f, 0.0, float(stats.norm.sf(beta))
    )


def beta_sum_cdf(t: float, k: int) -> float:
    """``P(U_1 + ... + U_k <= t)`` for i.i.d. ``U_i ~ Beta(2, 2)`` and ``0 <= t <= 1``.

    For ``t <= 1`` the box constraints ``U_i <= 1`` are implied, so the
    probability is an integral of ``prod 6 u_i (1 - u_i)`` over the simplex
    ``sum u <= t``. Expanding the product and using the Dirichlet integral
    ``int_{sum u <= t} prod u_i^{k_i} du = t^{sum k_i + k} prod k_i! /
    (sum k_i + k)!`` gives

        6^k sum_{j=0}^{k} C(k, j) (-2)^j t^{2k+j} / (2k+j)!
    """
    if not 0.0 <= t <= 1.0:
        raise ValueError(f"the closed form holds for 0 <= t <= 1; got t={t}")
    total = sum(
        comb(k, j) * (-2.0) ** j * t ** (2 * k + j) / factorial(2 * k + j)
        for j in range(k + 1)
    )
    return float(6.0**k * total)


def _beta_sum_quantile(p: float, k: int) -> float:
    if not 0.0 < p <= beta_sum_cdf(1.0, k):
        raise ValueError(
            f"p={p} is outside (0, {beta_sum_cdf(1.0, k):.3g}], "
            "where the closed form holds"
        )
    return float(
        optimize.brentq(lambda t: beta_sum_cdf(t, k) - p, 0.0, 1.0, xtol=1e-15)
    )


def beta_sum_problem(
    k: int = 6,
    p: float = 1e-5,
    lo: float = 80.0,
    scale: float = 40.0,
    bounds: tuple[float, float] | None = (1.5, 7.0),
) -> AnalyticProblem:
    """``k`` i.i.d. ``lo + scale Beta(2, 2)``; event: their sum below a threshold.

    ``gamma`` is chosen so that the exact probability is (to solver precision)
    ``p``; ``p_exact`` is the closed form at that ``gamma``.
    """
    t = _beta_sum_quantile(p, k)
    base = Product([ScaledBeta(2.0, 2.0, lo, scale, bounds) for _ in range(k)])

    def f(x: FloatArray) -> FloatArray:
        return x.sum(axis=1)

    return AnalyticProblem(
        f"beta_sum_k{k}", base, f, k * lo + scale * t, beta_sum_cdf(t, k)
    )


def mixed_problem(
    p_beta: float = 1e-2, p_normal: float = 1e-3, dim: int = 4
) -> AnalyticProblem:
    """Three ``Beta(2, 2)`` on ``[0, 1]`` and ``N(0, I_dim)``, both extreme at once.

    ``f(x) = max(sum(beta part) - t, beta - u^T z)`` with ``gamma = 0``, so
    ``p = P(sum <= t) Phi(-beta) = p_beta p_normal``.
    """
    k = 3
    t = _beta_sum_quantile(p_beta, k)
    beta = float(stats.norm.isf(p_normal))
    u = np.ones(dim) / np.sqrt(dim)
    base = Product(
        [ScaledBeta(2.0, 2.0) for _ in range(k)]
        + [FixedCovNormal(np.zeros(dim), cov=np.eye(dim))]
    )

    def f(x: FloatArray) -> FloatArray:
        return np.maximum(x[:, :k].sum(axis=1) - t, beta - x[:, k:] @ u)

    p_exact = beta_sum_cdf(t, k) * float(stats.norm.sf(beta))
    return AnalyticProblem("mixed_beta_normal", base, f, 0.0, p_exact)


def four_branch_problem() -> AnalyticProblem:
    """The four-branch series system (Au & Beck 2001, example 2; ``k = 7``).

    ``X ~ N(0, I_2)`` and ``f = min(g_1, .., g_4)`` with

        g_1,2 = 3 + 0.1 (x1 - x2)^2 -+ (x1 + x2) / sqrt(2)
        g_3,4 = +-(x1 - x2) + 7 / sqrt(2)

    and failure ``f <= 0``. In the rotated coordinates ``u = (x1 + x2) /
    sqrt(2)``, ``v = (x1 - x2) / sqrt(2)`` (independent standard normals) the
    failure set is ``|v| >= 3.5`` or ``|u| >= 3 + 0.2 v^2``, so

        p = 2 Phi(-3.5) + int_{|v| < 3.5} phi(v) 2 Phi(-(3 + 0.2 v^2)) dv

    computed by adaptive quadrature: ``p = 2.2228e-3``.
    """
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))

    def f(x: FloatArray) -> FloatArray:
        along, across = x[:, 0] + x[:, 1], x[:, 0] - x[:, 1]
        bowl = 3.0 + 0.1 * across**2
        return np.minimum.reduce(
            [
                bowl - along / np.sqrt(2),
                bowl + along / np.sqrt(2),
                across + 7 / np.sqrt(2),
                -across + 7 / np.sqrt(2),
            ]
        )

    inside, _ = integrate.quad(
        lambda v: stats.norm.pdf(v) * 2 * stats.norm.sf(3 + 0.2 * v * v),
        -3.5,
        3.5,
        epsabs=1e-15,
        epsrel=1e-12,
    )
    p_exact = 2 * float(stats.norm.sf(3.5)) + inside
    return AnalyticProblem(
        "four_branch", base, f, 0.0, p_exact, reference="quadrature over v"
    )
