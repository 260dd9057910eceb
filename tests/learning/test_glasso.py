import numpy as np
import pytest
from scipy import linalg

from avrisk.learning.prior.glasso import fit_sparse_gaussian, off_diagonal_sparsity


def chain_ensemble(rng, m=20, d=40):
    """m draws of a d-dim Gaussian with a chain-structured (tridiagonal) precision."""
    lower = np.eye(d) + np.diag(np.full(d - 1, 0.6), -1)
    cov = linalg.inv(lower @ lower.T)
    scales = np.r_[np.full(d - 4, 0.01), np.ones(4)]  # weights vs biases
    return rng.multivariate_normal(np.zeros(d), cov, size=m) * scales


def test_a_small_ensemble_gives_a_sparse_positive_definite_precision(rng):
    x = chain_ensemble(rng)
    fit = fit_sparse_gaussian(x, target_density=0.05)
    p = fit.precision.toarray()
    assert p.shape == (40, 40)
    assert np.array_equal(p, p.T)
    linalg.cholesky(p)  # raises unless positive definite
    assert fit.min_eigenvalue > 0
    assert 0.9 <= fit.sparsity < 1.0  # sparse, but some pairs linked
    assert fit.sparsity == off_diagonal_sparsity(p)
    assert np.allclose(fit.mean, x.mean(axis=0))
    assert 0.0 < fit.shrinkage <= 1.0


def test_the_precision_is_on_the_scale_of_the_data(rng):
    x = chain_ensemble(rng)
    fit = fit_sparse_gaussian(x, target_density=0.05)
    model_sd = np.sqrt(np.diag(linalg.inv(fit.precision.toarray())))
    ratio = model_sd / x.std(axis=0, ddof=1)
    assert np.all((ratio > 0.5) & (ratio < 1.5))


def test_a_coordinate_the_members_never_moved_gets_a_small_finite_variance(rng):
    x = chain_ensemble(rng, d=12)
    x[:, 3] = 0.7
    fit = fit_sparse_gaussian(x, target_density=0.1)
    assert np.isfinite(fit.precision.toarray()).all()
    assert fit.scale[3] > 0


def test_a_larger_alpha_gives_a_sparser_precision(rng):
    x = chain_ensemble(rng)
    loose = fit_sparse_gaussian(x, alpha=0.1)
    tight = fit_sparse_gaussian(x, alpha=0.3)
    assert tight.sparsity > loose.sparsity
    assert tight.alpha == 0.3


def test_bad_inputs_are_named_in_the_error():
    with pytest.raises(ValueError, match="m >= 2"):
        fit_sparse_gaussian(np.zeros((1, 5)))
    with pytest.raises(ValueError, match="finite"):
        fit_sparse_gaussian(np.full((3, 5), np.nan))
    with pytest.raises(ValueError, match="target_density"):
        fit_sparse_gaussian(np.ones((3, 5)), target_density=1.5)
