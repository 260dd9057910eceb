"""The moves' kernel: pCN, and steps along the seeds' principal directions."""

import numpy as np
import pytest
from scipy import stats

from avrisk.rare import FixedCovNormal, splitting_is, subset_simulation
from avrisk.rare.splitting_moves import _proposed, principal_directions


def _rotation(dim: int, seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((dim, dim)))
    return q


def test_principal_steps_keep_the_standard_normal_and_are_reversible():
    # z ~ N(0, I) and z' = A z + B eps: N(0, I) again, and E[z z'^T] = A
    # symmetric (the Gaussian autoregression is then reversible)
    n, v = 400_000, _rotation(3, 0)
    spread = np.array([0.05, 0.5, 2.0])  # the last saturates: sigma = 1
    rng = np.random.default_rng(1)
    z, eps = rng.standard_normal((2, n, 3))
    moved = _proposed(z, eps, 0.7, (v, spread))
    sigma = np.minimum(0.7 * spread, 1.0)
    a = v @ np.diag(np.sqrt(1 - sigma**2)) @ v.T
    tol = 5 * np.sqrt(2 / n)  # five standard errors of a (co)variance near 1
    assert np.abs(np.cov(moved.T) - np.eye(3)).max() < tol
    assert np.abs(z.T @ moved / n - a).max() < tol
    # spread 1 in every direction is pCN
    np.testing.assert_allclose(
        _proposed(z[:5], eps[:5], 0.3, (v, np.ones(3))),
        np.sqrt(1 - 0.09) * z[:5] + 0.3 * eps[:5] @ v.T,
        atol=1e-12,
    )


def test_principal_directions_follow_the_seeds_spread():
    v = _rotation(3, 2)
    seeds = np.random.default_rng(3).standard_normal((5000, 3)) * [0.1, 1.0, 2.0]
    vectors, spread = principal_directions(seeds @ v.T)
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(3), atol=1e-12)
    # shrinkage lifts the smallest spread a little (0.107 here)
    np.testing.assert_allclose(spread, [0.1, 1.0, 2.0], rtol=0.1)
    assert abs(vectors[:, 0] @ v[:, 0]) > 0.99  # the thin direction found
    assert principal_directions(seeds[:1]) is None


def _ridge(dim: int, width: float, p: float):
    """``f <= 0`` on a thin oblique ridge: ``|x0 - x1| / sqrt 2 < width``
    and ``(x0 + x1) / sqrt 2 > b``; exact ``p``."""
    inside = 2 * stats.norm.cdf(width) - 1
    b = stats.norm.isf(p / inside)

    def f(x):
        along = (x[:, 0] + x[:, 1]) / np.sqrt(2)
        across = np.abs(x[:, 0] - x[:, 1]) / np.sqrt(2)
        return np.maximum(b - along, across - width)

    return f, FixedCovNormal(np.zeros(dim), cov=np.eye(dim))


@pytest.mark.parametrize("steps", ["isotropic", "principal"])
def test_both_steps_find_p_on_a_thin_oblique_ridge(steps):
    f, base = _ridge(10, 0.05, 1e-6)
    est = subset_simulation(f, base, 0.0, n_particles=2000, seed=0, steps=steps)
    assert abs(np.log(est.p / 1e-6)) < 4 * est.stderr / est.p  # one seed
    sampled = splitting_is(f, base, 0.0, n_particles=2000, seed=0, steps=steps)
    assert abs(sampled.p - 1e-6) < 4 * sampled.stderr
