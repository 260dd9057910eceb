"""Normal family with a fixed covariance and a mean that CE moves in a box.

With precision ``P = Sigma0^-1`` fixed, the natural parameter is ``theta = P mu``,
the sufficient statistic is ``T(x) = x``, ``A(theta) = theta^T Sigma0 theta / 2 =
mu^T P mu / 2`` and the mean parameter is ``mu``. The CE projection

    argmax_mu  mu^T P m - mu^T P mu / 2   s.t.  ||mu - mu0||_inf <= max_shift

equals ``argmin (mu - m)^T P (mu - m)`` over the box: a box-constrained quadratic
program in the precision metric. :func:`box_qp` solves it exactly with a primal
active-set method whose sub-problems are sparse linear solves in ``P``, so a
sparse precision (the learned drivers' graphical-lasso prior of ``xi``) is
used as such.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import linalg, sparse
from scipy.sparse import linalg as sparse_linalg

from avrisk.rare.families.base import ExponentialFamily, FloatArray, as_sample_array

Matrix = np.ndarray | sparse.sparray | sparse.spmatrix


class FixedCovNormal(ExponentialFamily):
    """Multivariate normal ``N(mu, Sigma0)`` with ``Sigma0`` fixed.

    Parameters
    ----------
    mean : array_like of shape (D,)
        Mean of the base distribution; also the centre of the CE search box.
    cov : array_like or sparse matrix of shape (D, D), optional
        Covariance ``Sigma0``. Give exactly one of ``cov`` and ``precision``.
    precision : array_like or sparse matrix of shape (D, D), optional
        Precision ``Sigma0^-1``; kept sparse when given sparse.
    max_shift : float or array_like of shape (D,), optional
        CE search box ``|mu_i - mean_i| <= max_shift`` (the paper uses 0.01).
        ``None`` leaves the mean unconstrained.
    float32_samples : bool, default=False
        Round every sample to the nearest float32 (returned as float64). For
        a block that its consumer reads in float32 anyway (network weights):
        the samples then store losslessly in half the space. Densities are
        those of the continuous normal at the rounded points (a relative
        rounding of 6e-8 per coordinate).

    Attributes
    ----------
    mean : ndarray of shape (D,)
        Current mean ``mu``.
    center : ndarray of shape (D,)
        Centre of the search box (the base mean).

    Examples
    --------
    >>> import numpy as np
    >>> base = FixedCovNormal(np.zeros(3), cov=np.eye(3), max_shift=0.5)
    >>> base.project(np.array([2.0, 0.1, -1.0])).mean
    array([ 0.5,  0.1, -0.5])
    """

    def __init__(
        self,
        mean: Any,
        *,
        cov: Matrix | None = None,
        precision: Matrix | None = None,
        max_shift: float | Any | None = None,
        float32_samples: bool = False,
    ) -> None:
        mean = np.asarray(mean, dtype=np.float64)
        if mean.ndim != 1 or not np.isfinite(mean).all():
            raise ValueError(f"mean must be a finite 1-D array; got shape {mean.shape}")
        self.dim = self.n_stats = mean.size
        self.mean = self.center = mean
        if (cov is None) == (precision is None):
            raise ValueError("give exactly one of cov= and precision=")
        self.precision = _precision_matrix(cov, precision, self.dim)
        self._sparse = sparse.issparse(self.precision)
        dense = (
            self.precision.toarray()
            if sparse.issparse(self.precision)
            else self.precision
        )
        try:
            self._chol = linalg.cholesky(dense, lower=True)
        except linalg.LinAlgError as err:
            which = "cov" if cov is not None else "precision"
            raise ValueError(f"{which} must be symmetric positive definite") from err
        self._log_det_precision = 2.0 * float(np.log(np.diag(self._chol)).sum())
        # N(mu, I) (a block of standard-normal innovations): the Cholesky
        # factor is I, so the transforms skip the products by it.
        self._identity = bool(np.array_equal(dense, np.eye(self.dim)))
        self.max_shift = _as_shift(max_shift, self.dim)
        self.float32_samples = bool(float32_samples)

    def _at(self, mu: FloatArray) -> FixedCovNormal:
        """Same structure (covariance, box), mean ``mu``."""
        new = object.__new__(FixedCovNormal)
        new.__dict__.update(self.__dict__)
        new.mean = np.asarray(mu, dtype=np.float64).copy()
        return new

    def with_max_shift(self, max_shift: float | Any | None) -> FixedCovNormal:
        """Same distribution (and Cholesky factor), another CE search box."""
        new = self._at(self.mean)
        new.max_shift = _as_shift(max_shift, self.dim)
        return new

    def searched_coordinates(self) -> np.ndarray:
        """False where the box ``max_shift`` is 0, shape (D,)."""
        if self.max_shift is None:
            return np.ones(self.dim, dtype=bool)
        return self.max_shift > 0

    @property
    def std(self) -> FloatArray:
        """Marginal standard deviations ``sqrt(diag Sigma0)``, shape (D,).

        From the Cholesky factor ``P = L L^T``: ``Sigma0 = L^-T L^-1``, so
        ``diag Sigma0`` is the column sums of squares of ``L^-1``.
        """
        inv = linalg.solve_triangular(self._chol, np.eye(self.dim), lower=True)
        return np.sqrt((inv * inv).sum(axis=0))

    def _quad(self, d: FloatArray) -> FloatArray:
        """Row-wise ``d_i^T P d_i`` for ``d`` of shape (n, D) (``P`` symmetric)."""
        if self._identity:
            return (d * d).sum(axis=1)
        pd = np.asarray(self.precision @ d.T).T if self._sparse else d @ self.precision
        return (pd * d).sum(axis=1)

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples, shape (n, D): ``mu + L^-T z`` with ``P = L L^T``."""
        # row-major: row i independent of n
        return self.from_standard_normal(rng.standard_normal((n, self.dim)))

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """``z = L^T (x - mu)`` per row, shape (n, D), with ``P = L L^T``.

        ``L`` is the Cholesky factor of the precision (dense, also when the
        precision was given sparse), the one :meth:`sample` uses.
        """
        d = as_sample_array(x, self.dim) - self.mean
        return d if self._identity else d @ self._chol

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """``x = mu + L^-T z`` per row, shape (n, D) (rounded like :meth:`sample`)."""
        z = as_sample_array(z, self.dim, "z")
        if self._identity:
            x = self.mean + z
        else:
            y = linalg.solve_triangular(self._chol, z.T, lower=True, trans="T")
            x = self.mean + y.T
        if self.float32_samples:
            x = x.astype(np.float32).astype(np.float64)
        return x

    def log_prob(self, x: FloatArray) -> FloatArray:
        """Log-density of each row, shape (n,)."""
        d = as_sample_array(x, self.dim) - self.mean
        return 0.5 * (
            self._log_det_precision - self._quad(d) - self.dim * np.log(2 * np.pi)
        )

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """``T(x) = x``, shape (n, D)."""
        return as_sample_array(x, self.dim)

    @property
    def natural_params(self) -> FloatArray:
        """``theta = P mu``."""
        return np.asarray(self.precision @ self.mean)

    def with_natural_params(self, theta: FloatArray) -> FixedCovNormal:
        """The family at ``mu = P^-1 theta``."""
        return self._at(linalg.cho_solve((self._chol, True), theta))

    def exact_params(self) -> FloatArray:
        """``mu`` (the mean :meth:`sample` adds; ``P mu`` would not invert exactly)."""
        return self.mean.copy()

    def with_exact_params(self, params: FloatArray) -> FixedCovNormal:
        """The family at mean ``params``, shape (D,)."""
        mu = np.asarray(params, dtype=np.float64)
        if mu.shape != (self.dim,) or not np.isfinite(mu).all():
            raise ValueError(f"need a finite mean of shape ({self.dim},)")
        return self._at(mu)

    def log_partition(self) -> float:
        """``mu^T P mu / 2``."""
        return float(0.5 * self._quad(self.mean[None, :])[0])

    def mean_param(self) -> FloatArray:
        """``mu``."""
        return self.mean.copy()

    def project(self, m: FloatArray) -> FixedCovNormal:
        """Exact minimiser of ``(mu - m)^T P (mu - m)`` over the search box."""
        m = np.asarray(m, dtype=np.float64).reshape(self.dim)
        if not np.isfinite(m).all():
            raise ValueError("FixedCovNormal.project needs a finite target mean")
        if self.max_shift is None:
            return self._at(m)
        lo, hi = self.center - self.max_shift, self.center + self.max_shift
        return self._at(box_qp(self.precision, m, lo, hi))

    def in_search_box(self) -> bool:
        """Whether ``|mu - center| <= max_shift`` holds coordinate-wise."""
        if self.max_shift is None:
            return True
        return bool(
            (np.abs(self.mean - self.center) <= self.max_shift * (1 + 1e-12)).all()
        )

    def to_dict(self) -> dict[str, Any]:
        """Family name, mean, box centre and half-width (covariance omitted)."""
        shift = self.max_shift
        return {
            "family": "FixedCovNormal",
            "dim": self.dim,
            "mean": self.mean.tolist(),
            "center": self.center.tolist(),
            "max_shift": None if shift is None else shift.tolist(),
        }


def _precision_matrix(cov: Matrix | None, precision: Matrix | None, dim: int) -> Matrix:
    """The precision as given (sparse kept sparse, CSR) or as the inverse of ``cov``."""
    given = precision if precision is not None else cov
    if sparse.issparse(given):
        mat = sparse.csr_array(given, dtype=np.float64)
    else:
        mat = np.asarray(given, dtype=np.float64)
    if mat.shape != (dim, dim):
        raise ValueError(
            f"covariance/precision must have shape ({dim}, {dim}); got {mat.shape}"
        )
    if precision is None:
        dense = mat.toarray() if sparse.issparse(mat) else mat
        mat = np.linalg.inv(dense)
        mat = 0.5 * (mat + mat.T)
    return mat


def _as_shift(max_shift: Any, dim: int) -> FloatArray | None:
    if max_shift is None:
        return None
    shift = np.broadcast_to(np.asarray(max_shift, dtype=np.float64), (dim,)).copy()
    if not (shift >= 0).all():
        raise ValueError(f"max_shift must be >= 0; got {max_shift}")
    return shift


def box_qp(
    precision: Matrix, m: FloatArray, lo: FloatArray, hi: FloatArray
) -> FloatArray:
    """Minimise ``(x - m)^T P (x - m)`` subject to ``lo <= x <= hi``, exactly.

    Primal active-set method for a strictly convex QP: start at ``clip(m)``; on
    the current free set solve the equality-constrained problem (a linear solve
    in ``P_FF``, sparse when ``P`` is); step towards it until a bound blocks
    (that variable becomes bound), or, once the free solution is feasible,
    release the bound variable whose multiplier has the wrong sign. It stops
    when the KKT conditions hold, which for a convex problem is the optimum.

    Parameters
    ----------
    precision : ndarray or sparse matrix of shape (D, D)
        Symmetric positive definite ``P``.
    m : ndarray of shape (D,)
        Unconstrained minimiser.
    lo, hi : ndarray of shape (D,)
        Box, ``lo <= hi``.

    Returns
    -------
    ndarray of shape (D,)
    """
    is_sparse = sparse.issparse(precision)
    mat = sparse.csc_array(precision) if is_sparse else np.asarray(precision)
    x = np.clip(m, lo, hi)
    at_lo, at_hi = m < lo, m > hi
    scale = float(abs(mat).max()) * max(
        1.0, float(np.abs(m).max()), float(np.abs(hi - lo).max())
    )
    tol = 1e-12 * scale
    for _ in range(20 * x.size + 100):
        free = ~(at_lo | at_hi)
        z = x.copy()
        if free.any():
            bound = ~free
            rhs = np.zeros(int(free.sum()))
            if bound.any():
                rhs = np.asarray(mat[free][:, bound] @ (x[bound] - m[bound]))
            z[free] = m[free] - _solve(mat[free][:, free], rhs, is_sparse)
        outside = free & ((z < lo) | (z > hi))
        if outside.any():
            step = z - x
            target = np.where(z < lo, lo, hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                alpha_i = np.where(outside, (target - x) / step, np.inf)
            alpha = float(np.clip(alpha_i.min(), 0.0, 1.0))
            x = np.clip(x + alpha * step, lo, hi)
            blocked = outside & (alpha_i <= alpha + 1e-12)
            at_lo |= blocked & (z < lo)
            at_hi |= blocked & (z > hi)
            x[at_lo], x[at_hi] = lo[at_lo], hi[at_hi]
            continue
        x = z
        grad = np.asarray(mat @ (x - m))
        wrong = np.where(at_lo, -grad, 0.0) + np.where(at_hi, grad, 0.0)
        j = int(np.argmax(wrong))
        if wrong[j] <= tol:
            return x
        at_lo[j] = at_hi[j] = False
    raise RuntimeError("box_qp did not converge; is the precision positive definite?")


def _solve(a: Matrix, b: Any, is_sparse: bool) -> FloatArray:
    if is_sparse:
        return np.asarray(sparse_linalg.spsolve(sparse.csc_array(a), b)).reshape(-1)
    return linalg.solve(a, b, assume_a="pos")
