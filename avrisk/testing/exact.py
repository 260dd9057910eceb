"""Numerical tools for the exact answers of the problem suite.

Quadrature to near machine precision, the standard normal base of a
problem in ``d`` dimensions, and the probability of a union of independent
events computed without cancellation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import integrate

from avrisk.rare import FixedCovNormal

__all__ = ["quad", "standard_normal", "union_probability"]


def quad(fn: Callable[[float], float], lo: float, hi: float, points=None) -> float:
    """Adaptive quadrature to near machine precision (relative 1e-12)."""
    value, _ = integrate.quad(
        fn, lo, hi, epsabs=0.0, epsrel=1e-12, limit=500, points=points
    )
    return float(value)


def standard_normal(dim: int) -> FixedCovNormal:
    """``N(0, I_dim)``, the base of a problem in standard-normal space."""
    return FixedCovNormal(np.zeros(dim), cov=np.eye(dim))


def union_probability(p_i: np.ndarray) -> float:
    """``1 - prod(1 - p_i)``: one of independent events of probabilities ``p_i``."""
    return float(-np.expm1(np.sum(np.log1p(-p_i))))
