"""The exponential-family interface that the cross-entropy method works with.

A family instance is a *structure* (support, search box, fixed covariance ...)
together with one parameter value. Instances are immutable: the CE update
returns a new instance of the same structure.

In natural form a family has density ``p_theta(x) = h(x) exp(theta^T T(x) -
A(theta))`` with sufficient statistic ``T``, log-partition ``A`` and mean
parameter ``grad A(theta) = E_theta[T(X)]``. The CE update (the paper's
Algorithm 1) is the constrained moment-matching projection

    theta_new = argmax_{theta in search box} theta^T m - A(theta)

which, for ``m`` a mean parameter, is the maximum-likelihood fit of the family to
data whose average sufficient statistic is ``m``.
"""

from __future__ import annotations

import abc
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class ExponentialFamily(abc.ABC):
    """A parametrised distribution on ``R^dim`` in exponential-family form.

    Attributes
    ----------
    dim : int
        Dimension ``D`` of one sample.
    n_stats : int
        Length ``K`` of the sufficient statistic ``T(x)``.
    """

    dim: int
    n_stats: int

    @abc.abstractmethod
    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples.

        Row ``i`` must not depend on ``n`` (prefix consistency): the first ``m``
        rows of ``sample(n, rng)`` equal ``sample(m, rng)`` from the same state.
        Then a sample of a run depends only on the seed and its id.

        Parameters
        ----------
        n : int
            Number of samples.
        rng : numpy.random.Generator
            Source of randomness.

        Returns
        -------
        ndarray of shape (n, dim)
        """

    @abc.abstractmethod
    def log_prob(self, x: FloatArray) -> FloatArray:
        """Log-density of each row of ``x`` (``-inf`` outside the support).

        Parameters
        ----------
        x : ndarray of shape (n, dim)

        Returns
        -------
        ndarray of shape (n,)
        """

    @abc.abstractmethod
    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """Sufficient statistic ``T(x)`` of each row.

        Returns
        -------
        ndarray of shape (n, n_stats)
        """

    @property
    @abc.abstractmethod
    def natural_params(self) -> FloatArray:
        """Natural parameter ``theta``, an array of shape (n_stats,)."""

    @abc.abstractmethod
    def with_natural_params(self, theta: FloatArray) -> ExponentialFamily:
        """Return the family of the same structure at natural parameter ``theta``."""

    @abc.abstractmethod
    def log_partition(self) -> float:
        """Log-partition ``A(theta)`` at the current parameter."""

    @abc.abstractmethod
    def mean_param(self) -> FloatArray:
        """Mean parameter ``grad A(theta) = E_theta[T(X)]``, shape (n_stats,)."""

    @abc.abstractmethod
    def project(self, m: FloatArray) -> ExponentialFamily:
        """Exact solution of ``argmax theta^T m - A(theta)`` over the search box.

        Parameters
        ----------
        m : ndarray of shape (n_stats,)
            Target mean parameter (a weighted average of sufficient statistics).

        Returns
        -------
        ExponentialFamily
            The family of the same structure at the maximiser.
        """

    @abc.abstractmethod
    def in_search_box(self) -> bool:
        """Whether the current parameter lies in the CE search box."""

    @abc.abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description: family name and parameters."""

    def exact_params(self) -> FloatArray:
        """The current parameter as sampling uses it, shape (n_stats,).

        :meth:`with_exact_params` gives back a family that draws the same
        samples bit for bit (a run directory records proposals this way, to
        draw their samples again). The natural parameter by default; a family
        that samples from another parametrisation (:class:`FixedCovNormal`
        from its mean) overrides both methods.
        """
        return self.natural_params

    def with_exact_params(self, params: FloatArray) -> ExponentialFamily:
        """The family of the same structure at ``params`` of :meth:`exact_params`."""
        return self.with_natural_params(params)

    def searched_coordinates(self) -> np.ndarray:
        """Which coordinates the CE search may move, bool array of shape (dim,).

        All of them by default; a block whose search box is a single point
        (:class:`~avrisk.rare.families.normal.FixedCovNormal` with
        ``max_shift=0``) says False, and proposals in another
        parametrisation (:mod:`avrisk.rare.families.standard_space`) keep
        those coordinates as in the base.
        """
        return np.ones(self.dim, dtype=bool)

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """Map samples to independent standard normals: ``T(X) ~ N(0, I_dim)``.

        ``T`` is a bijection (up to the edges of a bounded support) with
        inverse :meth:`from_standard_normal`. Subset simulation
        (:mod:`avrisk.rare.splitting_moves`) moves its particles in that space,
        where a preconditioned Crank-Nicolson step leaves ``N(0, I)``, and so
        ``P0``, invariant.

        Parameters
        ----------
        x : ndarray of shape (n, dim)

        Returns
        -------
        ndarray of shape (n, dim)

        Raises
        ------
        NotImplementedError
            If the family has no such map (the default).
        """
        raise NotImplementedError(
            f"{type(self).__name__} has no map to standard normals; implement "
            "to_standard_normal and from_standard_normal to use it with splitting"
        )

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """Inverse of :meth:`to_standard_normal`: ``z ~ N(0, I)`` to samples.

        Parameters
        ----------
        z : ndarray of shape (n, dim)

        Returns
        -------
        ndarray of shape (n, dim)

        Raises
        ------
        NotImplementedError
            If the family has no such map (the default).
        """
        raise NotImplementedError(
            f"{type(self).__name__} has no map from standard normals; implement "
            "to_standard_normal and from_standard_normal to use it with splitting"
        )

    def __repr__(self) -> str:
        params = ", ".join(
            f"{k}={v!r}" for k, v in self.to_dict().items() if k != "family"
        )
        return f"{type(self).__name__}({params})"


def as_sample_array(x: Any, dim: int, name: str = "x") -> FloatArray:
    """Check and convert ``x`` to a float64 array of shape (n, dim).

    Raises
    ------
    ValueError
        If ``x`` cannot be read as an ``(n, dim)`` array of numbers.
    """
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1 and dim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}); got {arr.shape}")
    return arr
