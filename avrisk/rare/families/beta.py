"""Scaled Beta family on ``[lo, lo + scale]`` with a box-constrained CE update.

With ``u = (x - lo) / scale`` the density is ``u^(a-1) (1-u)^(b-1) / (B(a, b)
scale)``. In exponential-family form: natural parameter ``theta = (a, b)``,
sufficient statistic ``T(x) = (log u, log(1 - u))``, log-partition ``A = log B(a,
b)`` and mean parameter ``grad A = (psi(a) - psi(a+b), psi(b) - psi(a+b))``.

The CE projection maximises the concave function ``J(a, b) = a m1 + b m2 - log
B(a, b)`` over the box ``[lo_ab, hi_ab]^2``. It is solved exactly by nested
monotone root finding: for fixed ``a`` the best ``b`` solves ``psi(b) - psi(a+b)
= m2`` (left side increasing in ``b``), clipped to the box; the profile
``h(a) = J(a, b*(a))`` is concave with derivative ``m1 - psi(a) + psi(a +
b*(a))`` (envelope theorem), so the best ``a`` is the root of that decreasing
function, clipped to the box. Both roots are bracketed and found by Brent's
method to machine precision.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import optimize, special

from avrisk.rare.families.base import ExponentialFamily, FloatArray, as_sample_array

#: Box used when ``bounds=None``: wide enough to be effectively unconstrained.
UNCONSTRAINED_BOUNDS = (1e-6, 1e6)

# Keeps log u and log(1 - u) finite for samples that round onto the support edge.
_U_EPS = 1e-300

#: Standard-normal image of the ends of the support (``-Phi^-1`` of the smallest
#: normal double): keeps it finite for samples that round onto an edge.
Z_EDGE = float(-special.ndtri(np.finfo(float).tiny))


class ScaledBeta(ExponentialFamily):
    """Beta(a, b) scaled to ``[lo, lo + scale]``.

    Parameters
    ----------
    a, b : float
        Shape parameters, positive.
    lo : float
        Lower end of the support (same unit as the samples).
    scale : float
        Width of the support, positive.
    bounds : tuple of float or None, default=(1.5, 7.0)
        CE search box ``bounds[0] <= a, b <= bounds[1]`` (paper's choice).
        ``None`` means effectively unconstrained (``UNCONSTRAINED_BOUNDS``).

    Examples
    --------
    >>> import numpy as np
    >>> speed = ScaledBeta(2.0, 2.0, lo=10.0, scale=10.0)  # V ~ 10 Beta(2,2) + 10
    >>> x = speed.sample(4, np.random.default_rng(0))
    >>> bool(((x >= 10) & (x <= 20)).all())
    True
    >>> round(float(speed.mean_param()[0]), 4)  # E[log U] = psi(2) - psi(4)
    -0.8333
    """

    n_stats = 2

    def __init__(
        self,
        a: float,
        b: float,
        lo: float = 0.0,
        scale: float = 1.0,
        bounds: tuple[float, float] | None = (1.5, 7.0),
    ) -> None:
        self.a, self.b = float(a), float(b)
        self.lo, self.scale = float(lo), float(scale)
        self.bounds = None if bounds is None else (float(bounds[0]), float(bounds[1]))
        self.dim = 1
        if not (self.a > 0 and self.b > 0):
            raise ValueError(f"ScaledBeta needs a > 0 and b > 0; got a={a}, b={b}")
        if not (np.isfinite(self.lo) and self.scale > 0 and np.isfinite(self.scale)):
            raise ValueError(
                f"ScaledBeta needs a finite lo and scale > 0; got lo={lo}, "
                f"scale={scale}"
            )
        box_lo, box_hi = self._box
        if not 0 < box_lo < box_hi:
            raise ValueError(
                f"ScaledBeta bounds must satisfy 0 < low < high; got {bounds}"
            )
        if not self.in_search_box():
            raise ValueError(
                f"ScaledBeta(a={self.a}, b={self.b}) lies outside its search box "
                f"bounds={bounds}; widen the bounds so they contain a and b"
            )

    @property
    def _box(self) -> tuple[float, float]:
        return UNCONSTRAINED_BOUNDS if self.bounds is None else self.bounds

    def _u(self, x: FloatArray) -> FloatArray:
        return (as_sample_array(x, 1)[:, 0] - self.lo) / self.scale

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples, shape (n, 1)."""
        return (self.lo + self.scale * rng.beta(self.a, self.b, size=n))[:, None]

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """``z = Phi^-1(F(x))``, shape (n, 1), ``F`` this Beta's distribution function.

        Each tail is computed from its own side (``F`` below the median, ``1 -
        F`` above it), so both keep full relative precision; the ends of the
        support map to ``-Z_EDGE`` and ``Z_EDGE``.
        """
        u = np.clip(self._u(x), 0.0, 1.0)
        lower = special.betainc(self.a, self.b, u)
        upper = special.betaincc(self.a, self.b, u)
        with np.errstate(divide="ignore"):
            z = np.where(lower < upper, special.ndtri(lower), -special.ndtri(upper))
        return np.clip(z, -Z_EDGE, Z_EDGE)[:, None]

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """``x = lo + scale F^-1(Phi(z))``, shape (n, 1) (each tail from its side)."""
        z = as_sample_array(z, 1, "z")[:, 0]
        u = np.where(
            z < 0,
            special.betaincinv(self.a, self.b, special.ndtr(z)),
            special.betainccinv(self.a, self.b, special.ndtr(-z)),
        )
        return (self.lo + self.scale * u)[:, None]

    def log_prob(self, x: FloatArray) -> FloatArray:
        """Log-density [log 1/unit of x], shape (n,); ``-inf`` off the support."""
        u = self._u(x)
        inside = (u >= 0) & (u <= 1)
        uc = np.clip(u, 0.0, 1.0)
        with np.errstate(divide="ignore"):
            out = (
                special.xlogy(self.a - 1, uc)
                + special.xlog1py(self.b - 1, -uc)
                - special.betaln(self.a, self.b)
                - np.log(self.scale)
            )
        return np.where(inside, out, -np.inf)

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """``(log u, log(1 - u))`` per row, shape (n, 2)."""
        u = np.clip(self._u(x), _U_EPS, 1.0 - np.finfo(float).epsneg)
        return np.stack([np.log(u), np.log1p(-u)], axis=1)

    @property
    def natural_params(self) -> FloatArray:
        """``(a, b)``."""
        return np.array([self.a, self.b])

    def with_natural_params(self, theta: FloatArray) -> ScaledBeta:
        """Same support and box, shape parameters ``theta = (a, b)``.

        Unlike the constructor this accepts parameters outside the search box:
        such a family is a valid distribution, it is just not a CE candidate.
        """
        a, b = (float(v) for v in theta)
        if not (a > 0 and b > 0):
            raise ValueError(f"ScaledBeta needs a > 0 and b > 0; got a={a}, b={b}")
        new = object.__new__(ScaledBeta)
        new.__dict__.update(self.__dict__, a=a, b=b)
        return new

    def log_partition(self) -> float:
        """``log B(a, b)``."""
        return float(special.betaln(self.a, self.b))

    def mean_param(self) -> FloatArray:
        """``(E log U, E log(1 - U)) = (psi(a) - psi(a+b), psi(b) - psi(a+b))``."""
        d_ab = special.digamma(self.a + self.b)
        return np.array(
            [special.digamma(self.a) - d_ab, special.digamma(self.b) - d_ab]
        )

    def project(self, m: FloatArray) -> ScaledBeta:
        """Exact box-constrained maximiser of ``a m1 + b m2 - log B(a, b)``."""
        m1, m2 = (float(v) for v in np.asarray(m, dtype=np.float64).reshape(2))
        if not (np.isfinite(m1) and np.isfinite(m2)):
            raise ValueError(f"ScaledBeta.project needs a finite target; got {m}")
        lo, hi = self._box
        a = _clipped_decreasing_root(
            lambda a: m1 - _profile_slope(a, m2, lo, hi), lo, hi
        )
        return self.with_natural_params((a, _best_b(a, m2, lo, hi)))

    def in_search_box(self) -> bool:
        """Whether ``a`` and ``b`` both lie in the search box."""
        lo, hi = self._box
        return lo <= self.a <= hi and lo <= self.b <= hi

    def to_dict(self) -> dict[str, Any]:
        """Family name, shape parameters, support and search box."""
        return {
            "family": "ScaledBeta",
            "a": self.a,
            "b": self.b,
            "lo": self.lo,
            "scale": self.scale,
            "bounds": None if self.bounds is None else list(self.bounds),
        }


def _clipped_decreasing_root(g: Any, lo: float, hi: float) -> float:
    """Root of a decreasing function ``g`` on ``[lo, hi]``, clipped to the ends."""
    g_lo = g(lo)
    if g_lo <= 0:
        return lo
    g_hi = g(hi)
    if g_hi >= 0:
        return hi
    return float(optimize.brentq(g, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps))


def _best_b(a: float, m2: float, lo: float, hi: float) -> float:
    """Box-constrained maximiser over ``b`` of ``b m2 - log B(a, b)`` (``a`` fixed)."""
    return _clipped_decreasing_root(
        lambda b: m2 - (special.digamma(b) - special.digamma(a + b)), lo, hi
    )


def _profile_slope(a: float, m2: float, lo: float, hi: float) -> float:
    """``psi(a) - psi(a + b*(a))``: ``m1`` minus this is the profile's derivative."""
    b = _best_b(a, m2, lo, hi)
    return float(special.digamma(a) - special.digamma(a + b))
