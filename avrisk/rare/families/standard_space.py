"""Proposals that shift the mean in the base's standard-normal space.

Any base ``P0`` with a map to independent standard normals ``z = T(x)``
(:meth:`~avrisk.rare.families.base.ExponentialFamily.to_standard_normal`: each
Beta through its quantile transform, a correlated normal block through its
Cholesky factor) gives the family

    q_mu(x) = p0(x) exp(mu^T T(x) - |mu|^2 / 2),

the law of ``x = T^-1(z)`` with ``z ~ N(mu, I)``: an exponential family with
carrier ``p0``, sufficient statistic ``T(x)``, natural and mean parameter
``mu`` and log-partition ``|mu|^2 / 2``. The CE update is the weighted mean of
the elites' ``z``. This is the standard-space cross-entropy of reliability
analysis (OpenTURNS's ``StandardSpaceCrossEntropyImportanceSampling``).

Why it matters: a base family's own proposals may be unable to reach a rare
event. A Beta block's shape parameters must stay below twice the base's for
its weights to have finite variance (the search box of the bundled
scenarios), so no Beta proposal concentrates on a corner of the support; the
weight of a standard-space shift, ``p0 / q_mu = exp(-mu^T z + |mu|^2 / 2)``, is
log-normal under ``q_mu`` and has finite variance for every ``mu``.

Coordinates that the base does not search (a block whose CE box is a point,
like the learned drivers' ``xi`` with ``xi_search: 0``;
:meth:`~avrisk.rare.families.base.ExponentialFamily.searched_coordinates`)
keep ``mu_i = 0`` (unless the family is told to shift them, ``searched``);
the others are clipped to ``|mu_i| <= max_shift``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray, as_sample_array

__all__ = ["DEFAULT_MAX_SHIFT", "StandardSpaceShift"]

#: Largest mean shift per coordinate [standard deviations of z]: beyond it a
#: Beta quantile transform loses precision, and no event of interest lies there.
DEFAULT_MAX_SHIFT = 8.0


class StandardSpaceShift(ExponentialFamily):
    """``T^-1(N(mu, I))`` for a base ``P0`` with its standard-normal map ``T``.

    Parameters
    ----------
    base : ExponentialFamily
        ``P0``; must implement ``to_standard_normal`` / ``from_standard_normal``.
    mean : array_like of shape (D,), optional
        The shift ``mu`` of ``z`` (default 0: the family is then ``P0``).
    max_shift : float, default=DEFAULT_MAX_SHIFT
        CE search box ``|mu_i| <= max_shift`` on the searched coordinates.
    searched : array_like of bool, shape (D,), optional
        Coordinates :meth:`project` may shift (default: the base's
        ``searched_coordinates()``).

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import ScaledBeta, Product
    >>> unit = ScaledBeta(2, 2, lo=0, scale=1)
    >>> base = Product([unit, unit])
    >>> q = StandardSpaceShift(base).project(np.array([3.0, -1.0]))
    >>> q.mean, bool(q.sample(1000, np.random.default_rng(0))[:, 0].mean() > 0.8)
    (array([ 3., -1.]), True)
    """

    def __init__(
        self,
        base: ExponentialFamily,
        mean: Any = None,
        *,
        max_shift: float = DEFAULT_MAX_SHIFT,
        searched: Any = None,
    ) -> None:
        if not max_shift > 0:
            raise ValueError(f"max_shift must be > 0; got {max_shift}")
        self.base = base
        self.dim = self.n_stats = base.dim
        if searched is None:
            searched = base.searched_coordinates()
        self.searched = np.asarray(searched, dtype=bool)
        if self.searched.shape != (self.dim,):
            raise ValueError(
                f"searched must be {self.dim} booleans; got shape {self.searched.shape}"
            )
        self.max_shift = float(max_shift)
        self.mean = np.zeros(self.dim) if mean is None else self._checked(mean)

    def _checked(self, mean: Any) -> FloatArray:
        mu = np.asarray(mean, dtype=np.float64)
        if mu.shape != (self.dim,) or not np.isfinite(mu).all():
            raise ValueError(
                f"mean must be {self.dim} finite numbers; got {mean!r:.80}"
            )
        return mu.copy()

    def _at(self, mean: FloatArray) -> StandardSpaceShift:
        new = object.__new__(StandardSpaceShift)
        new.__dict__.update(self.__dict__, mean=self._checked(mean))
        return new

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``T^-1(mu + e)``, ``e ~ N(0, I)``, shape (n, D) (prefix-consistent)."""
        return self.base.from_standard_normal(
            rng.standard_normal((n, self.dim)) + self.mean
        )

    def log_prob(self, x: FloatArray) -> FloatArray:
        """``log p0(x) + mu^T T(x) - |mu|^2 / 2``, shape (n,)."""
        x = as_sample_array(x, self.dim)
        z = self.base.to_standard_normal(x)
        return self.base.log_prob(x) + z @ self.mean - 0.5 * self.mean @ self.mean

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """``T(x)``, the standard normals of the base, shape (n, D)."""
        return self.base.to_standard_normal(as_sample_array(x, self.dim))

    @property
    def natural_params(self) -> FloatArray:
        """``mu``."""
        return self.mean.copy()

    def with_natural_params(self, theta: FloatArray) -> StandardSpaceShift:
        """Same base and box, shift ``theta``."""
        return self._at(theta)

    def log_partition(self) -> float:
        """``|mu|^2 / 2``."""
        return float(0.5 * self.mean @ self.mean)

    def mean_param(self) -> FloatArray:
        """``E[T(X)] = mu``."""
        return self.mean.copy()

    def project(self, m: FloatArray) -> StandardSpaceShift:
        """``m`` clipped to the box, 0 on the coordinates the base does not search."""
        m = np.asarray(m, dtype=np.float64).reshape(self.dim)
        if not np.isfinite(m).all():
            raise ValueError("StandardSpaceShift.project needs a finite target")
        shift = np.clip(m, -self.max_shift, self.max_shift)
        return self._at(np.where(self.searched, shift, 0.0))

    def in_search_box(self) -> bool:
        """Whether ``mu`` is within the box and 0 where the base is not searched."""
        inside = np.abs(self.mean) <= self.max_shift
        return bool(inside.all() and (self.mean[~self.searched] == 0).all())

    def searched_coordinates(self) -> np.ndarray:
        """The base's."""
        return self.searched.copy()

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """``T(x) - mu``: standard normals under this family."""
        return self.sufficient_stat(x) - self.mean

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """``T^-1(z + mu)``."""
        return self.base.from_standard_normal(
            as_sample_array(z, self.dim, "z") + self.mean
        )

    def to_dict(self) -> dict[str, Any]:
        """Family name, shift and box (the base is the run's ``P0``)."""
        return {
            "family": "StandardSpaceShift",
            "mean": [float(v) for v in self.mean],
            "max_shift": self.max_shift,
            "searched": int(self.searched.sum()),
        }
