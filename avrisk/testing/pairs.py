"""Pairs of rare-event problems with exact ``p_A``, ``p_B`` and ``p_AB``.

For the paired comparison (:mod:`avrisk.rare.paired`): two versions ``A``
and ``B`` of a black box on the same ``X ~ N(0, I_D)``, each failing on a
half-space, ``f_A(x) = beta_A - u_A . x`` and ``f_B(x) = beta_B - u_B . x``
(``|u| = 1``, failure ``f <= 0``). ``u_A . X`` and ``u_B . X`` are standard
normals with correlation ``rho = u_A . u_B``, so

    p_A = Phi(-beta_A),  p_B = Phi(-beta_B),
    p_AB = int_{beta_A}^inf phi(z) Phi((rho z - beta_B) / sqrt(1 - rho^2)) dz

(a one-dimensional quadrature, to near machine precision; ``min(p_A, p_B)``
for ``rho = 1``, ``max(0, p_A + p_B - 1)`` for ``rho = -1``). The discordant
share ``r = P(A xor B) / P(A or B)`` ranges from 0 (the same failure set) to 1
(disjoint sets):

* :func:`nested_pair` -- ``u_A = u_B``, ``beta_B > beta_A``: ``B``'s failure
  set inside ``A``'s (a fix, no regression), ``r = 1 - p_B / p_A``;
* :func:`overlapping_pair` -- equal ``beta``, normals at the angle that makes
  the discordant share ``r``;
* :func:`disjoint_pair` -- ``u_B = -u_A``: the sets never meet.

:func:`pair_problem` builds one by name (``nested_r0.05_p1e-04_d10``) and
:data:`PAIR_SUITE` names the cases ``benchmarks/ab_coverage.py`` runs.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from scipy import integrate, optimize, stats

from avrisk.rare import FixedCovNormal
from avrisk.rare.families.base import FloatArray
from avrisk.testing.problems import AnalyticProblem

__all__ = [
    "PAIR_SUITE",
    "AnalyticPair",
    "HalfSpacePair",
    "both_tails",
    "disjoint_pair",
    "nested_pair",
    "overlapping_pair",
    "pair_problem",
]

#: The cases of the coverage and efficiency benchmark, by discordant share:
#: nested sets (a small and a large fix), overlapping sets, disjoint sets
#: with equal and with doubled ``p``.
PAIR_SUITE = (
    "nested_r0.05_p1e-04_d10",
    "nested_r0.5_p1e-04_d10",
    "overlap_r0.1_p1e-04_d10",
    "overlap_r0.3_p1e-04_d10",
    "disjoint_ratio1_p1e-04_d10",
    "disjoint_ratio2_p1e-04_d10",
)


def both_tails(beta_a: float, beta_b: float, rho: float) -> float:
    """``P(Z_A >= beta_A, Z_B >= beta_B)``, standard normals of correlation ``rho``."""
    if rho >= 1.0:
        return float(min(stats.norm.sf(beta_a), stats.norm.sf(beta_b)))
    if rho <= -1.0:
        return float(max(0.0, stats.norm.sf(beta_a) + stats.norm.sf(beta_b) - 1.0))
    s = math.sqrt(1.0 - rho * rho)

    def density(z: float) -> float:
        return float(stats.norm.pdf(z) * stats.norm.sf((beta_b - rho * z) / s))

    value, _ = integrate.quad(density, beta_a, np.inf, epsabs=0.0, epsrel=1e-12)
    return float(value)


@dataclass(frozen=True)
class AnalyticPair:
    """Two versions of a black box on one base, with exact probabilities.

    Attributes
    ----------
    name : str
    base : ExponentialFamily
    f : callable
        ``(n, D) -> (n, 2)``: ``(f_A, f_B)`` of each row.
    gamma : float
        Failure threshold of both, ``f <= gamma``.
    p_a, p_b, p_ab : float
        ``P(A)``, ``P(B)`` and ``P(A and B)``, exact.
    """

    name: str
    base: FixedCovNormal
    f: HalfSpacePair
    gamma: float
    p_a: float
    p_b: float
    p_ab: float

    @property
    def difference(self) -> float:
        """``p_B - p_A``."""
        return self.p_b - self.p_a

    @property
    def ratio(self) -> float:
        """``p_B / p_A``."""
        return self.p_b / self.p_a

    @property
    def discordant_share(self) -> float:
        """``r = P(A xor B) / P(A or B)``."""
        union = self.p_a + self.p_b - self.p_ab
        return (union - self.p_ab) / union

    def version(self, which: int) -> AnalyticProblem:
        """Version ``A`` (0) or ``B`` (1) alone, as a problem of its own."""
        pair = self.f

        def f(x: FloatArray) -> FloatArray:
            return pair.single(x, which)

        p = (self.p_a, self.p_b)[which]
        return AnalyticProblem(f"{self.name}_{'AB'[which]}", self.base, f, 0.0, p)


@dataclass(frozen=True)
class HalfSpacePair:
    """``(beta_A - u_A . x, beta_B - u_B . x)``, ``u`` of shape (2, D)."""

    beta: tuple[float, float]
    u: FloatArray

    def single(self, x: FloatArray, which: int) -> FloatArray:
        """One version's values, shape (n,)."""
        return self.beta[which] - x @ self.u[which]

    def __call__(self, x: FloatArray) -> FloatArray:
        """Both versions' values, shape (n, 2)."""
        return np.asarray(self.beta) - x @ self.u.T


def _half_spaces(
    name: str, beta: tuple[float, float], angle: float, dim: int
) -> AnalyticPair:
    """Half-spaces at ``beta``, normals ``angle`` [rad] apart, in ``D = dim``."""
    u = np.zeros((2, dim))
    u[0, 0] = 1.0
    u[1, 0], u[1, 1] = math.cos(angle), math.sin(angle)
    base = FixedCovNormal(np.zeros(dim), cov=np.eye(dim))
    return AnalyticPair(
        name,
        base,
        HalfSpacePair(beta, u),
        0.0,
        float(stats.norm.sf(beta[0])),
        float(stats.norm.sf(beta[1])),
        both_tails(*beta, math.cos(angle)),
    )


def nested_pair(r: float, p: float = 1e-4, dim: int = 10) -> AnalyticPair:
    """``B``'s failure set inside ``A``'s (``p_A = p``): ``p_B = (1 - r) p``."""
    beta = (float(stats.norm.isf(p)), float(stats.norm.isf((1.0 - r) * p)))
    return _half_spaces(f"nested_r{r:g}_p{p:.0e}_d{dim}", beta, 0.0, dim)


def overlapping_pair(r: float, p: float = 1e-4, dim: int = 10) -> AnalyticPair:
    """``p_A = p_B = p``, normals at the angle that makes the discordant share ``r``."""
    beta = float(stats.norm.isf(p))

    def share(angle: float) -> float:
        both = both_tails(beta, beta, math.cos(angle))
        return (2.0 * p - 2.0 * both) / (2.0 * p - both)

    angle = optimize.brentq(lambda a: share(a) - r, 1e-6, math.pi / 2, xtol=1e-14)
    return _half_spaces(f"overlap_r{r:g}_p{p:.0e}_d{dim}", (beta, beta), angle, dim)


def disjoint_pair(ratio: float = 1.0, p: float = 1e-4, dim: int = 10) -> AnalyticPair:
    """Opposite half-spaces (they never meet), ``p_A = p`` and ``p_B = ratio p``."""
    beta = (float(stats.norm.isf(p)), float(stats.norm.isf(ratio * p)))
    return _half_spaces(f"disjoint_ratio{ratio:g}_p{p:.0e}_d{dim}", beta, math.pi, dim)


_NAME = re.compile(
    r"(?P<kind>nested|overlap|disjoint)_(?P<key>r|ratio)(?P<value>[0-9.e+-]+)"
    r"_p(?P<p>[0-9.e+-]+)_d(?P<dim>\d+)"
)


def pair_problem(name: str) -> AnalyticPair:
    """The pair a name describes (``nested_r0.05_p1e-04_d10``, ``disjoint_ratio2_...``).

    Raises
    ------
    ValueError
        For a name of no family.

    Examples
    --------
    >>> pair = pair_problem("overlap_r0.1_p1e-04_d10")
    >>> round(pair.discordant_share, 6), round(pair.ratio, 6)
    (0.1, 1.0)
    """
    match = _NAME.fullmatch(name)
    kinds = {"nested": ("r", nested_pair), "overlap": ("r", overlapping_pair)}
    kinds["disjoint"] = ("ratio", disjoint_pair)
    if match is None or kinds[match["kind"]][0] != match["key"]:
        raise ValueError(
            f"no pair problem {name!r}: nested_r<r>_p<p>_d<D>, overlap_r<r>_p<p>_d<D> "
            "or disjoint_ratio<ratio>_p<p>_d<D>"
        )
    build = kinds[match["kind"]][1]
    return build(float(match["value"]), float(match["p"]), int(match["dim"]))
