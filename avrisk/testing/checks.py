"""Conformance checks that every family and estimator must pass.

They raise ``AssertionError`` with a message naming what failed. Statistical
checks use z-scores against the quantity's own standard error with a stated
false-failure rate per check (``Z_TOL = 5`` standard errors: about 6e-7
two-sided).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import stats
from scipy.special import logsumexp

from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.results import Estimate
from avrisk.testing.problems import AnalyticProblem

Z_TOL = 5.0


def check_family(
    family: ExponentialFamily, rng: np.random.Generator, n: int = 20_000
) -> None:
    """Check that a family's parts agree with each other.

    1. Samples have shape (n, dim) and finite log-density, and row ``i`` does
       not depend on ``n`` (prefix consistency).
    2. Sample mean of ``T(X)`` equals ``mean_param()`` within ``Z_TOL`` stderr.
    3. ``mean_param()`` is the gradient of ``A(theta)`` (central differences).
    4. ``log_prob`` is normalised and consistent with sampling: for a nearby
       family ``q`` of the same structure, ``E_p[q(X)/p(X)] = 1``.
    5. ``project(mean_param())`` is a fixed point (moment matching recovers the
       parameter) and lands in the search box.
    6. ``project(m)`` of another family's mean lands in the box and is no worse
       than the box-feasible starting point in ``theta^T m - A(theta)``.
    """
    seed = int(rng.integers(2**63))
    x = family.sample(n, np.random.default_rng(seed))
    assert x.shape == (n, family.dim), f"sample shape {x.shape} != {(n, family.dim)}"
    np.testing.assert_array_equal(
        family.sample(n // 3, np.random.default_rng(seed)),
        x[: n // 3],
        err_msg="sample is not prefix-consistent: row i depends on n",
    )
    logp = family.log_prob(x)
    assert logp.shape == (n,) and np.isfinite(logp).all(), (
        "log_prob not finite on samples"
    )

    t = family.sufficient_stat(x)
    se = t.std(axis=0, ddof=1) / np.sqrt(n)
    z = np.abs(t.mean(axis=0) - family.mean_param()) / np.maximum(se, 1e-300)
    assert z.max() < Z_TOL, (
        f"sample mean of T differs from mean_param: max z={z.max():.1f}"
    )

    theta = family.natural_params
    grad = np.empty_like(theta)
    for i in range(theta.size):
        h = 1e-5 * max(1.0, abs(theta[i]))
        e = np.zeros_like(theta)
        e[i] = h
        a_plus = family.with_natural_params(theta + e).log_partition()
        a_minus = family.with_natural_params(theta - e).log_partition()
        grad[i] = (a_plus - a_minus) / (2 * h)
    np.testing.assert_allclose(grad, family.mean_param(), rtol=1e-5, atol=1e-6)

    other = family.with_natural_params(
        theta * (1 + 0.05 * rng.standard_normal(theta.size))
    )
    log_ratio = other.log_prob(x) - logp
    ratio = np.exp(log_ratio - log_ratio.max())
    mean_ratio = np.exp(logsumexp(log_ratio) - np.log(n))
    se_ratio = ratio.std(ddof=1) * np.exp(log_ratio.max()) / np.sqrt(n)
    assert abs(mean_ratio - 1) < Z_TOL * se_ratio + 1e-9, (
        f"E_p[q/p] = {mean_ratio:.4f} +- {se_ratio:.4f}, not 1: "
        "log_prob and sample disagree"
    )

    fixed = family.project(family.mean_param())
    assert fixed.in_search_box(), "project(mean_param()) left the search box"
    np.testing.assert_allclose(
        fixed.natural_params,
        theta,
        rtol=1e-6,
        atol=1e-8,
        err_msg="project(mean_param()) does not recover the parameter",
    )

    m = other.mean_param()
    proj = family.project(m)
    assert proj.in_search_box(), "project(m) left the search box"

    def objective(fam: ExponentialFamily) -> float:
        return float(fam.natural_params @ m - fam.log_partition())

    assert objective(proj) >= objective(family) - 1e-9, (
        "project(m) is worse than the start"
    )


def check_standard_normal_map(
    family: ExponentialFamily, rng: np.random.Generator, n: int = 20_000
) -> None:
    """Check that a family's map to standard normals is a bijection onto N(0, I).

    1. ``from_standard_normal(to_standard_normal(x)) = x`` on samples (to a
       relative 1e-8 of the sample's spread; float32-rounded samples come back
       rounded the same way).
    2. ``to_standard_normal`` of samples is ``N(0, I)``: every coordinate
       passes a Kolmogorov-Smirnov test whose critical distance holds the
       false-failure rate at the ``Z_TOL`` level, ``sqrt(ln(2 / alpha) / (2 n))``
       with ``alpha = 2 Phi(-Z_TOL)``; sample means within ``Z_TOL / sqrt(n)``
       of 0; sample covariances within ``Z_TOL sqrt(2 / n)`` of ``I``.

    Together they make ``from_standard_normal`` of ``N(0, I)`` draws samples
    of the family.
    """
    x = family.sample(n, rng)
    z = family.to_standard_normal(x)
    assert z.shape == (n, family.dim) and np.isfinite(z).all(), (
        f"to_standard_normal gave shape {z.shape} or non-finite values"
    )
    spread = np.ptp(x, axis=0)
    np.testing.assert_allclose(
        family.from_standard_normal(z),
        x,
        rtol=1e-8,
        atol=1e-8 * float(spread.max()),
        err_msg="from_standard_normal does not invert to_standard_normal",
    )
    alpha = 2 * stats.norm.sf(Z_TOL)
    critical = np.sqrt(np.log(2 / alpha) / (2 * n))
    distance = max(stats.kstest(col, "norm").statistic for col in z.T)
    assert distance < critical, (
        f"to_standard_normal of samples is not N(0, 1): KS distance {distance:.4f} "
        f">= {critical:.4f}"
    )
    assert np.abs(z.mean(axis=0)).max() < Z_TOL / np.sqrt(n), (
        f"to_standard_normal of samples has mean {z.mean(axis=0)}, not 0"
    )
    cov = np.atleast_2d(np.cov(z.T))
    assert np.abs(cov - np.eye(family.dim)).max() < Z_TOL * np.sqrt(2 / n), (
        f"to_standard_normal of samples has covariance {cov}, not I"
    )


def check_estimator(
    estimate: Callable[[AnalyticProblem, int], Estimate],
    problem: AnalyticProblem,
    seed: int = 0,
    z_tol: float = Z_TOL,
) -> Estimate:
    """Run ``estimate(problem, seed)`` and check it against the exact answer.

    Checks the result's contract (shapes, ``n_evals``, a proper interval, JSON
    round trip) and that ``|p_hat - p| <= z_tol * stderr``.
    """
    import json

    est = estimate(problem, seed)
    assert isinstance(est, Estimate)
    lo, hi = est.ci
    assert 0.0 <= lo <= est.p <= hi <= 1.0 and hi > 0.0, (
        f"bad interval {est.ci} for p={est.p}"
    )
    assert est.n_evals >= est.n_samples > 0
    assert problem.gamma in est.by_gamma
    json.loads(json.dumps(est.to_dict()))
    assert est.stderr > 0, f"{problem.name}: zero standard error (hits: {est.n_hits})"
    z = abs(est.p - problem.p_exact) / est.stderr
    assert z <= z_tol, (
        f"{problem.name}: p_hat={est.p:.4g} +- {est.stderr:.2g} "
        f"but exact p={problem.p_exact:.4g}"
        f" (z={z:.1f})"
    )
    return est
