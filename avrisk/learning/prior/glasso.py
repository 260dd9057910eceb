"""A sparse Gaussian over ensemble members: Ledoit-Wolf, then the graphical lasso.

The paper fits ``xi ~ N(mu0, Sigma0)`` to ``m`` ensemble heads in ``d = 404 >
m`` dimensions, with the graphical lasso (Friedman, Hastie, Tibshirani 2008) for
a sparse ``Sigma0^-1``. With ``m = 20`` the sample covariance has rank 19 and
``GraphicalLasso`` on raw data is fragile (it can fail to converge or return a
matrix that is not positive definite), so the fit is::

    mu0   = mean of the members                                   (d,)
    s     = per-coordinate standard deviation, floored            (d,)
    Z     = (members - mu0) / s                                    (m, d)
    C     = Ledoit-Wolf shrunk covariance of Z (full rank)         (d, d)
    Pz    = graphical lasso precision of C (covariance="precomputed")
    Sigma0^-1 = diag(1/s) Pz diag(1/s), tiny entries set to exactly 0

Working on the standardised scale makes one ``alpha`` mean the same for every
coordinate (weights and biases, mean and log-variance rows differ in scale).
The result is checked: symmetric, positive definite (Cholesky), and its
off-diagonal sparsity is reported.

References
----------
.. [1] J. Friedman, T. Hastie, R. Tibshirani, "Sparse inverse covariance
   estimation with the graphical lasso", Biostatistics 9(3), 2008.
.. [2] O. Ledoit, M. Wolf, "A well-conditioned estimator for large-dimensional
   covariance matrices", J. Multivariate Analysis 88(2), 2004.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, sparse

__all__ = ["SparseGaussianFit", "fit_sparse_gaussian", "off_diagonal_sparsity"]


@dataclass(frozen=True)
class SparseGaussianFit:
    """A Gaussian with a sparse precision, fitted to a few samples.

    Attributes
    ----------
    mean : ndarray of shape (D,)
        Sample mean.
    precision : scipy.sparse.csr_array of shape (D, D)
        Sparse, symmetric positive definite ``Sigma^-1``.
    scale : ndarray of shape (D,)
        Per-coordinate standard deviations used to standardise (floored).
    alpha : float
        Graphical-lasso penalty actually used (standardised scale).
    shrinkage : float
        Ledoit-Wolf shrinkage intensity in ``[0, 1]``.
    n_samples : int
        ``m``.
    n_iter : int
        Graphical-lasso iterations.
    sparsity : float
        Fraction of off-diagonal precision entries that are exactly zero.
    min_eigenvalue : float
        Smallest eigenvalue of the standardised precision ``Pz`` (> 0).
    marginal_std_ratio : float
        Median over coordinates of the model's marginal standard deviation
        over the sample's.
    """

    mean: NDArray[np.float64]
    precision: sparse.csr_array
    scale: NDArray[np.float64]
    alpha: float
    shrinkage: float
    n_samples: int
    n_iter: int
    sparsity: float
    min_eigenvalue: float
    marginal_std_ratio: float

    def to_meta(self) -> dict[str, Any]:
        """JSON-serialisable summary (no arrays)."""
        return {
            "alpha": self.alpha,
            "shrinkage": self.shrinkage,
            "n_samples": self.n_samples,
            "n_iter": self.n_iter,
            "sparsity": self.sparsity,
            "nnz": int(self.precision.nnz),
            "min_eigenvalue": self.min_eigenvalue,
            "marginal_std_ratio": self.marginal_std_ratio,
        }


def off_diagonal_sparsity(precision: Any) -> float:
    """Fraction of off-diagonal entries that are exactly zero.

    Parameters
    ----------
    precision : ndarray or sparse matrix of shape (D, D)

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [1.0, 0.0, 2.0]])
    >>> round(off_diagonal_sparsity(p), 4)
    0.6667
    """
    p = sparse.csr_array(precision)
    d = p.shape[0]
    if d < 2:
        return 1.0
    p.eliminate_zeros()
    off = p.nnz - int(np.count_nonzero(p.diagonal()))
    return 1.0 - off / (d * d - d)


def _glasso_blocks(
    emp: NDArray[np.float64], alpha: float, max_iter: int, tol: float
) -> tuple[NDArray[np.float64], int]:
    """Graphical-lasso precision of a covariance, block by block.

    Exact screening (Witten, Friedman, Simon 2011; Mazumder, Hastie 2012): the
    solution is block diagonal over the connected components of the graph
    ``|emp_ij| > alpha``, so each component is solved on its own and a
    singleton ``i`` has precision ``1 / emp_ii``.
    """
    from scipy.sparse.csgraph import connected_components
    from sklearn.covariance import GraphicalLasso

    d = emp.shape[0]
    adj = np.abs(emp) > alpha
    np.fill_diagonal(adj, False)
    n_comp, labels = connected_components(sparse.csr_array(adj), directed=False)
    pz = np.zeros_like(emp)
    n_iter = 0
    for c in range(n_comp):
        idx = np.flatnonzero(labels == c)
        if idx.size == 1:
            pz[idx[0], idx[0]] = 1.0 / emp[idx[0], idx[0]]
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gl = GraphicalLasso(
                alpha=alpha,
                covariance="precomputed",
                max_iter=max_iter,
                tol=tol,
                assume_centered=True,
            ).fit(emp[np.ix_(idx, idx)])
        pz[np.ix_(idx, idx)] = gl.precision_
        n_iter = max(n_iter, int(gl.n_iter_))
    if d == 0:  # pragma: no cover
        raise ValueError("empty covariance")
    return pz, n_iter


def _sparse_precision(
    emp: NDArray[np.float64], alpha: float, max_iter: int, tol: float, zero_tol: float
) -> tuple[NDArray[np.float64], int, float]:
    """One graphical-lasso fit at ``alpha``: symmetric, tiny entries zeroed, checked.

    Returns the standardised precision ``Pz``, the solver's iterations and
    ``Pz``'s smallest eigenvalue; raises FloatingPointError if ``Pz`` is not
    finite and positive definite.
    """
    pz, n_iter = _glasso_blocks(emp, alpha, max_iter, tol)
    pz = 0.5 * (pz + pz.T)
    diag = np.sqrt(np.diag(pz))
    pz[np.abs(pz) <= zero_tol * np.outer(diag, diag)] = 0.0
    np.fill_diagonal(pz, diag**2)
    eig = float(linalg.eigvalsh(pz, subset_by_index=[0, 0])[0])
    if not np.isfinite(pz).all() or eig <= 0:
        raise FloatingPointError(f"precision not positive definite (min eig {eig})")
    return pz, n_iter, eig


def fit_sparse_gaussian(
    samples: NDArray[Any],
    *,
    alpha: float | None = None,
    target_density: float = 0.01,
    max_iter: int = 100,
    tol: float = 1e-4,
    zero_tol: float = 1e-8,
    scale_floor: float = 1e-3,
    max_retries: int = 4,
) -> SparseGaussianFit:
    """Fit ``N(mean, Sigma)`` with a sparse ``Sigma^-1`` to ``m`` samples.

    Parameters
    ----------
    samples : array_like of shape (m, D)
        ``m >= 2`` samples (e.g. ensemble heads), ``D`` possibly ``> m``.
    alpha : float, optional
        Graphical-lasso penalty on the standardised, shrunk covariance; larger
        is sparser. Default: the ``1 - target_density`` quantile of the
        absolute off-diagonal entries, so that about ``target_density`` of the
        pairs can be linked (Ledoit-Wolf shrinks the correlations of a few
        samples strongly, so a fixed ``alpha`` would mean different things for
        different ``m``). Doubled and retried if the solver fails.
    target_density : float, default=0.01
        See ``alpha``; in ``(0, 1)``.
    max_iter : int, default=100
        Graphical-lasso iterations.
    tol : float, default=1e-4
        Graphical-lasso dual-gap tolerance.
    zero_tol : float, default=1e-8
        Standardised precision entries with ``|Pz_ij| <= zero_tol sqrt(Pz_ii
        Pz_jj)`` are set to exactly 0.
    scale_floor : float, default=1e-3
        Coordinates whose standard deviation is below ``scale_floor`` times the
        median one are given that floor (a coordinate the members never moved,
        such as a weight of a hidden unit that is never active, gets a small
        variance rather than an infinite precision).
    max_retries : int, default=4
        Times ``alpha`` is doubled after a failure.

    Returns
    -------
    SparseGaussianFit

    Raises
    ------
    ValueError
        If fewer than 2 samples, non-finite values or a bad ``target_density``
        are given.
    RuntimeError
        If no ``alpha`` tried gives a positive definite precision.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).standard_normal((20, 30))
    >>> fit = fit_sparse_gaussian(x, target_density=0.05)
    >>> fit.precision.shape, fit.sparsity > 0.9, fit.min_eigenvalue > 0
    ((30, 30), True, True)
    """
    from sklearn.covariance import LedoitWolf

    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"samples must have shape (m, D) with m >= 2; got {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("samples must be finite")
    if not 0.0 < target_density < 1.0:
        raise ValueError(f"target_density must be in (0, 1); got {target_density}")
    m, d = x.shape
    mean = x.mean(axis=0)
    std = x.std(axis=0, ddof=1)
    positive = std[std > 0]
    ref = float(np.median(positive)) if positive.size else 1.0
    scale = np.maximum(std, scale_floor * ref)
    z = (x - mean) / scale
    lw = LedoitWolf(assume_centered=True).fit(z)
    emp = lw.covariance_
    if alpha is None:
        off = np.abs(emp[~np.eye(d, dtype=bool)])
        alpha = float(np.quantile(off, 1.0 - target_density)) if off.size else 1.0

    a = float(alpha)
    last_error: Exception | None = None
    for _ in range(max_retries + 1):
        try:
            pz, n_iter, eig = _sparse_precision(emp, a, max_iter, tol, zero_tol)
            break
        except (FloatingPointError, ValueError, linalg.LinAlgError) as err:
            last_error = err
            a *= 2.0
    else:
        raise RuntimeError(
            f"graphical lasso failed up to alpha={a / 2:g}: {last_error}"
        ) from last_error

    precision = pz / np.outer(scale, scale)
    linalg.cholesky(precision, lower=True)  # raises if not positive definite
    p_sparse = sparse.csr_array(precision)
    p_sparse.eliminate_zeros()
    cov_diag = np.diag(linalg.inv(pz)) * scale**2
    return SparseGaussianFit(
        mean=mean,
        precision=p_sparse,
        scale=scale,
        alpha=a,
        shrinkage=float(lw.shrinkage_),
        n_samples=m,
        n_iter=n_iter,
        sparsity=off_diagonal_sparsity(p_sparse),
        min_eigenvalue=eig,
        marginal_std_ratio=float(
            np.median(np.sqrt(cov_diag) / np.maximum(std, 1e-300))
        ),
    )
