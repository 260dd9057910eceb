"""Proposals that shift and scale the base's standard normals, coordinate by coordinate.

The law of ``x = T^-1(z)`` with ``z ~ N(mu, diag(v))`` for a base ``P0`` with
its standard-normal map ``T``
(:meth:`~avrisk.rare.families.base.ExponentialFamily.to_standard_normal`):

    q(x) = p0(x) prod_i N(z_i; mu_i, v_i) / N(z_i; 0, 1),   z = T(x).

In natural form the carrier is ``p0(x) exp(|z|^2 / 2)``, the sufficient
statistic ``(z, z^2)``, the natural parameter ``(mu / v, -1 / (2 v))`` and the
log-partition ``sum_i mu_i^2 / (2 v_i) + log(v_i) / 2``. With ``v = 1`` it is
:class:`~avrisk.rare.families.standard_space.StandardSpaceShift`.

Why it matters: a rare event's conditional law is often narrower than ``P0``
along the coordinates that reach it (a sum of squares held small, a corner of
several Beta blocks), and over many such coordinates a proposal of unit
variance pays for the mismatch in every one of them: its weights'
log-variance grows with their number. The weight of a component narrower
than ``P0`` has unbounded tails, so this family is meant for mixtures with a
defensive share of ``P0`` (:class:`~avrisk.rare.mixture_em.MixtureProposal`),
which bounds every weight.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray, as_sample_array
from avrisk.rare.families.standard_space import DEFAULT_MAX_SHIFT, StandardSpaceShift

__all__ = ["VARIANCE_RANGE", "StandardSpaceNormal"]

#: Smallest and largest variance of ``z_i`` a projection gives.
VARIANCE_RANGE = (0.6, 4.0)


class StandardSpaceNormal(ExponentialFamily):
    """``T^-1(N(mu, diag(v)))`` for a base ``P0`` with its standard-normal map ``T``.

    Parameters
    ----------
    base : ExponentialFamily
        ``P0``; must implement ``to_standard_normal`` / ``from_standard_normal``.
    mean : array_like of shape (D,), optional
        ``mu`` (default 0).
    variance : array_like of shape (D,), optional
        ``v``, positive (default 1).
    max_shift : float, default=DEFAULT_MAX_SHIFT
        Projection box ``|mu_i| <= max_shift``.
    searched : array_like of bool, shape (D,), optional
        Coordinates :meth:`project` may move (default: the base's
        ``searched_coordinates()``); the others keep ``mu_i = 0, v_i = 1``.

    Examples
    --------
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    >>> q = StandardSpaceNormal(base, [3.0, 0.0], [0.25, 1.0])
    >>> x = q.sample(100_000, np.random.default_rng(0))
    >>> (x.mean(axis=0).round(1) + 0.0).tolist(), x.std(axis=0).round(1).tolist()
    ([3.0, 0.0], [0.5, 1.0])
    >>> w = np.exp(base.log_prob(x) - q.log_prob(x))
    >>> bool(abs(w[x[:, 0] > 2.5].sum() / len(x) - 0.00621) < 0.0003)
    True
    """

    def __init__(
        self,
        base: ExponentialFamily,
        mean: Any = None,
        variance: Any = None,
        *,
        max_shift: float = DEFAULT_MAX_SHIFT,
        searched: Any = None,
    ) -> None:
        shift = StandardSpaceShift(
            base, mean, max_shift=max_shift, searched=searched
        )  # checks the base, the mean and the box
        self.base = base
        self.dim = base.dim
        self.n_stats = 2 * base.dim
        self.searched = shift.searched
        self.max_shift = shift.max_shift
        self.mean = shift.mean
        self.variance = (
            np.ones(self.dim) if variance is None else self._checked(variance)
        )

    @classmethod
    def of_shift(
        cls, shift: StandardSpaceShift, variance: Any = None
    ) -> StandardSpaceNormal:
        """``shift``'s mean, box and searched coordinates; ``variance`` (default 1)."""
        return cls(
            shift.base,
            shift.mean,
            variance,
            max_shift=shift.max_shift,
            searched=shift.searched,
        )

    def _checked(self, variance: Any) -> FloatArray:
        v = np.asarray(variance, dtype=np.float64)
        if v.shape != (self.dim,) or not (np.isfinite(v) & (v > 0)).all():
            raise ValueError(
                f"variance must be {self.dim} positive numbers; got {variance!r:.80}"
            )
        return v.copy()

    def _at(self, mean: FloatArray, variance: FloatArray) -> StandardSpaceNormal:
        return StandardSpaceNormal(
            self.base,
            mean,
            variance,
            max_shift=self.max_shift,
            searched=self.searched,
        )

    def log_ratio(self, z: FloatArray) -> FloatArray:
        """``log(q / p0)`` at standard normals ``z`` of shape (n, D), shape (n,)."""
        z = as_sample_array(z, self.dim, "z")
        return (
            -0.5 * ((z - self.mean) ** 2 / self.variance - z * z).sum(axis=1)
            - 0.5 * np.log(self.variance).sum()
        )

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``T^-1(mu + sqrt(v) e)``, ``e ~ N(0, I)``, (n, D), prefix-consistent."""
        e = rng.standard_normal((n, self.dim))
        return self.base.from_standard_normal(self.mean + np.sqrt(self.variance) * e)

    def log_prob(self, x: FloatArray) -> FloatArray:
        """``log p0(x) + log(q / p0)(T(x))``, shape (n,)."""
        x = as_sample_array(x, self.dim)
        return self.base.log_prob(x) + self.log_ratio(self.base.to_standard_normal(x))

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """``(z, z^2)`` with ``z = T(x)``, shape (n, 2 D)."""
        z = self.base.to_standard_normal(as_sample_array(x, self.dim))
        return np.hstack([z, z * z])

    @property
    def natural_params(self) -> FloatArray:
        """``(mu / v, -1 / (2 v))``, shape (2 D,)."""
        return np.concatenate([self.mean / self.variance, -0.5 / self.variance])

    def with_natural_params(self, theta: FloatArray) -> StandardSpaceNormal:
        """The member of natural parameter ``theta`` (its second half negative)."""
        theta = np.asarray(theta, dtype=np.float64).reshape(self.n_stats)
        variance = -0.5 / theta[self.dim :]
        return self._at(theta[: self.dim] * variance, variance)

    def log_partition(self) -> float:
        """``sum_i mu_i^2 / (2 v_i) + log(v_i) / 2``."""
        return float(
            0.5 * (self.mean**2 / self.variance).sum()
            + 0.5 * np.log(self.variance).sum()
        )

    def mean_param(self) -> FloatArray:
        """``E[(z, z^2)] = (mu, v + mu^2)``, shape (2 D,)."""
        return np.concatenate([self.mean, self.variance + self.mean**2])

    def project(self, m: FloatArray) -> StandardSpaceNormal:
        """The fit to mean statistic ``m = (E z, E z^2)``, clipped to the box.

        ``mu = E z`` within ``|mu_i| <= max_shift``, ``v = E z^2 - mu^2``
        within ``VARIANCE_RANGE``; ``mu_i = 0, v_i = 1`` where not searched.
        """
        m = np.asarray(m, dtype=np.float64).reshape(self.n_stats)
        if not np.isfinite(m).all():
            raise ValueError("StandardSpaceNormal.project needs a finite target")
        first, second = m[: self.dim], m[self.dim :]
        mean = np.clip(first, -self.max_shift, self.max_shift)
        variance = np.clip(second - first**2, *VARIANCE_RANGE)
        return self._at(
            np.where(self.searched, mean, 0.0), np.where(self.searched, variance, 1.0)
        )

    def in_search_box(self) -> bool:
        """Whether ``mu``, ``v`` are in the box, ``(0, 1)`` where not searched."""
        low, high = VARIANCE_RANGE
        inside = (np.abs(self.mean) <= self.max_shift) & (
            (self.variance >= low) & (self.variance <= high)
        )
        still = (self.mean[~self.searched] == 0) & (self.variance[~self.searched] == 1)
        return bool(inside.all() and still.all())

    def searched_coordinates(self) -> np.ndarray:
        """The coordinates it may move."""
        return self.searched.copy()

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """``(T(x) - mu) / sqrt(v)``: standard normals under this family."""
        z = self.base.to_standard_normal(as_sample_array(x, self.dim))
        return (z - self.mean) / np.sqrt(self.variance)

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """``T^-1(mu + sqrt(v) z)``."""
        z = as_sample_array(z, self.dim, "z")
        return self.base.from_standard_normal(self.mean + np.sqrt(self.variance) * z)

    def to_dict(self) -> dict[str, Any]:
        """Family name, mean, variance and box (the base is the run's ``P0``)."""
        return {
            "family": "StandardSpaceNormal",
            "mean": [float(v) for v in self.mean],
            "variance": [float(v) for v in self.variance],
            "max_shift": self.max_shift,
            "searched": int(self.searched.sum()),
        }
