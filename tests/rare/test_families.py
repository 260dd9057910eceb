import numpy as np
import pytest
from scipy import optimize, sparse, special, stats

from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.rare.families import box_qp
from avrisk.rare.families.beta import Z_EDGE
from avrisk.testing import check_family, check_standard_normal_map

FAMILIES = {
    "beta-s": ScaledBeta(2.0, 2.0, lo=80.0, scale=40.0),
    "beta-w": ScaledBeta(1.6, 6.5, lo=-3.6, scale=7.2),
    "beta-unbounded": ScaledBeta(0.7, 0.9, bounds=None),
    "normal-dense": FixedCovNormal(np.array([1.0, -2.0]), cov=[[2.0, 0.5], [0.5, 1.0]]),
    "normal-sparse": FixedCovNormal(
        np.zeros(5), precision=sparse.eye_array(5) * 4.0, max_shift=0.01
    ),
    "product": Product(
        [ScaledBeta(2, 2, 10, 10), FixedCovNormal(np.ones(3), cov=np.eye(3))]
    ),
}


@pytest.mark.parametrize("family", FAMILIES.values(), ids=FAMILIES.keys())
def test_family_passes_the_conformance_check(family, rng):
    check_family(family, rng)


def _sparse_correlated_precision(dim):
    """A tridiagonal (sparse) precision with correlations between neighbours."""
    return sparse.diags_array(
        [np.full(dim - 1, -0.4), np.full(dim, 1.5), np.full(dim - 1, -0.4)],
        offsets=[-1, 0, 1],
        format="csr",
    )


@pytest.mark.parametrize(
    "family",
    [
        *FAMILIES.values(),
        FixedCovNormal(np.arange(4.0), precision=_sparse_correlated_precision(4)),
        FixedCovNormal(np.ones(3), cov=np.eye(3) * 0.01, float32_samples=True),
    ],
    ids=[*FAMILIES.keys(), "normal-sparse-correlated", "normal-float32"],
)
def test_family_maps_onto_independent_standard_normals(family, rng):
    check_standard_normal_map(family, rng)


def test_fixed_cov_normal_samples_are_its_map_of_the_generators_normals():
    fam = FixedCovNormal(np.ones(4), precision=_sparse_correlated_precision(4))
    z = np.random.default_rng(3).standard_normal((50, 4))
    np.testing.assert_array_equal(
        fam.sample(50, np.random.default_rng(3)), fam.from_standard_normal(z)
    )


def test_scaled_beta_maps_its_lower_tail_at_full_precision_and_edges_to_finite_z():
    fam = ScaledBeta(2.0, 2.0)  # on [0, 1]: tiny u are represented exactly
    z = np.array([[-30.0], [-8.0], [0.0], [5.0]])
    x = fam.from_standard_normal(z)
    assert 0 < x[0, 0] < 1e-90
    np.testing.assert_allclose(fam.to_standard_normal(x), z, rtol=1e-9, atol=1e-12)
    cdf = stats.beta(2, 2).cdf(x[:2, 0])
    np.testing.assert_allclose(cdf, stats.norm.cdf(z[:2, 0]), rtol=1e-9)
    scaled = ScaledBeta(2.0, 2.0, lo=80.0, scale=40.0)
    edges = scaled.to_standard_normal(np.array([[80.0], [120.0]]))
    np.testing.assert_array_equal(edges[:, 0], [-Z_EDGE, Z_EDGE])
    np.testing.assert_allclose(scaled.from_standard_normal(edges)[:, 0], [80, 120])


def test_scaled_beta_log_prob_matches_scipy():
    fam = ScaledBeta(2.5, 4.0, lo=10.0, scale=10.0)
    x = np.linspace(10.01, 19.99, 50)[:, None]
    expected = stats.beta(2.5, 4.0, loc=10.0, scale=10.0).logpdf(x[:, 0])
    np.testing.assert_allclose(fam.log_prob(x), expected, rtol=1e-12)


def test_scaled_beta_log_prob_is_minus_infinity_off_the_support():
    fam = ScaledBeta(2.0, 2.0, lo=80.0, scale=40.0)
    assert np.all(fam.log_prob(np.array([[79.9], [120.1]])) == -np.inf)


def test_fixed_cov_normal_log_prob_matches_scipy_with_dense_and_sparse_precision(rng):
    a = rng.standard_normal((6, 6))
    cov = a @ a.T + 6 * np.eye(6)
    mean = rng.standard_normal(6)
    x = rng.standard_normal((20, 6))
    expected = stats.multivariate_normal(mean, cov).logpdf(x)
    prec = np.linalg.inv(cov)
    for fam in (
        FixedCovNormal(mean, cov=cov),
        FixedCovNormal(mean, precision=prec),
        FixedCovNormal(mean, precision=sparse.csr_array(prec)),
    ):
        np.testing.assert_allclose(fam.log_prob(x), expected, rtol=1e-10)


def test_fixed_cov_normal_samples_have_the_given_covariance(rng):
    cov = np.array([[2.0, 0.8], [0.8, 1.0]])
    x = FixedCovNormal(np.zeros(2), precision=np.linalg.inv(cov)).sample(200_000, rng)
    # entries of a sample covariance have stderr ~ sqrt((s_ii s_jj + s_ij^2) / n) < 0.01
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.05)


def _beta_objective(ab, m):
    return ab[0] * m[0] + ab[1] * m[1] - special.betaln(ab[0], ab[1])


@pytest.mark.parametrize("bounds", [(1.5, 7.0), (0.5, 3.0), None])
def test_beta_projection_matches_an_independent_bounded_solver(bounds, rng):
    box = (1e-6, 1e6) if bounds is None else bounds
    fam = ScaledBeta(
        max(2.0, box[0]), min(2.0, box[1]) if box[1] < 2 else 2.0, bounds=bounds
    )
    for _ in range(25):
        # targets: mean parameters of random Betas, some far outside the box
        a, b = np.exp(rng.uniform(np.log(0.3), np.log(30.0), size=2))
        m = ScaledBeta(a, b, bounds=None).mean_param()
        ours = fam.project(m).natural_params
        start = np.clip([2.0, 2.0], box[0], min(box[1], 50.0))
        ref = optimize.minimize(
            lambda ab, m=m: -_beta_objective(ab, m),
            start,
            jac=lambda ab, m=m: (
                -(m - (special.digamma(ab) - special.digamma(ab.sum())))
            ),
            bounds=[(box[0], min(box[1], 1e3))] * 2,
            method="L-BFGS-B",
            options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10_000},
        )
        assert _beta_objective(ours, m) >= -ref.fun - 1e-10
        assert box[0] <= ours.min() and ours.max() <= box[1]
        if (
            bounds is None
        ):  # unconstrained: the Beta maximum-likelihood fit recovers (a, b)
            np.testing.assert_allclose(ours, [a, b], rtol=1e-8)


def test_beta_projection_of_an_inside_target_is_plain_moment_matching():
    m = ScaledBeta(3.0, 5.0).mean_param()
    np.testing.assert_allclose(
        ScaledBeta(2, 2).project(m).natural_params, [3.0, 5.0], rtol=1e-10
    )


def _random_spd(rng, d, density):
    a = sparse.random_array((d, d), density=density, rng=rng).toarray()
    p = a @ a.T + np.diag(rng.uniform(0.5, 2.0, d))
    return p


@pytest.mark.parametrize("d,density", [(3, 1.0), (20, 0.2), (120, 0.02)])
def test_box_qp_matches_bounded_least_squares(d, density, rng):
    for _ in range(10):
        p = _random_spd(rng, d, density)
        m = rng.normal(scale=2.0, size=d)
        lo, hi = -np.abs(rng.normal(size=d)), np.abs(rng.normal(size=d))
        chol = np.linalg.cholesky(p)  # p = L L^T, so (x-m)^T p (x-m) = |L^T (x-m)|^2
        ref = optimize.lsq_linear(
            chol.T, chol.T @ m, bounds=(lo, hi), method="bvls", tol=1e-14
        )
        for prec in (p, sparse.csr_array(p)):
            x = box_qp(prec, m, lo, hi)
            assert np.all(x >= lo) and np.all(x <= hi)
            np.testing.assert_allclose(x, ref.x, atol=1e-8)


def test_box_qp_satisfies_the_kkt_conditions(rng):
    p = _random_spd(rng, 60, 0.05)
    m = rng.normal(scale=3.0, size=60)
    lo, hi = -np.ones(60) * 0.5, np.ones(60) * 0.5
    x = box_qp(sparse.csr_array(p), m, lo, hi)
    grad = p @ (x - m)
    free = (x > lo + 1e-12) & (x < hi - 1e-12)
    assert np.abs(grad[free]).max(initial=0.0) < 1e-9
    assert np.all(grad[x <= lo + 1e-12] >= -1e-9)  # pushing up would not help
    assert np.all(grad[x >= hi - 1e-12] <= 1e-9)


def test_normal_projection_respects_the_paper_box_around_the_base_mean(rng):
    d = 404
    mean = rng.normal(size=d)
    base = FixedCovNormal(mean, precision=sparse.eye_array(d) * 3.0, max_shift=0.01)
    proposal = base.project(mean + rng.normal(size=d))
    assert np.abs(proposal.mean - mean).max() <= 0.01 + 1e-12
    # a diagonal precision decouples the QP: the answer is the clipped target
    again = proposal.project(mean + 0.005)
    np.testing.assert_allclose(again.mean, mean + 0.005)
    assert np.array_equal(again.center, mean)


def test_product_log_prob_is_the_sum_of_its_blocks(rng):
    b1, b2 = ScaledBeta(2, 3, 0, 2), FixedCovNormal(np.zeros(2), cov=np.eye(2))
    prod = Product([b1, b2])
    x = prod.sample(10, rng)
    np.testing.assert_allclose(
        prod.log_prob(x), b1.log_prob(x[:, :1]) + b2.log_prob(x[:, 1:])
    )


def test_log_density_ratios_stay_finite_in_dimension_500(rng):
    d = 500
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    far = base.project(np.full(d, 1.5))  # ~ e^{-560} overlap per sample
    x = far.sample(100, rng)
    log_w = base.log_prob(x) - far.log_prob(x)
    assert np.isfinite(log_w).all()
    assert (
        log_w.max() < -300
    )  # weights far below 1e-130, still represented in log space


def test_bounds_that_exclude_the_base_parameters_are_rejected():
    with pytest.raises(ValueError, match=r"a=2.0.*outside its search box"):
        ScaledBeta(2.0, 2.0, bounds=(2.5, 7.0))


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(a=-1.0, b=2.0), "a > 0 and b > 0"),
        (dict(a=2.0, b=2.0, scale=0.0), "scale > 0"),
        (dict(a=2.0, b=2.0, bounds=(3.0, 1.0)), "0 < low < high"),
    ],
)
def test_scaled_beta_rejects_bad_parameters_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ScaledBeta(**kwargs)


def test_fixed_cov_normal_rejects_bad_input_naming_it():
    with pytest.raises(ValueError, match="exactly one of cov= and precision="):
        FixedCovNormal(np.zeros(2))
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        FixedCovNormal(np.zeros(2), cov=np.eye(3))
    with pytest.raises(ValueError, match="positive definite"):
        FixedCovNormal(np.zeros(2), cov=[[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="max_shift must be >= 0"):
        FixedCovNormal(np.zeros(2), cov=np.eye(2), max_shift=-1.0)


def test_log_prob_rejects_samples_of_the_wrong_dimension():
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        FixedCovNormal(np.zeros(3), cov=np.eye(3)).log_prob(np.zeros((4, 2)))


@pytest.mark.parametrize("as_sparse", [False, True])
def test_fixed_cov_normal_std_is_the_root_of_the_covariance_diagonal(as_sparse):
    rng = np.random.default_rng(3)
    a = rng.standard_normal((5, 5))
    cov = a @ a.T + 0.5 * np.eye(5)
    prec = np.linalg.inv(cov)
    fam = FixedCovNormal(
        np.zeros(5), precision=sparse.csr_array(prec) if as_sparse else prec
    )
    np.testing.assert_allclose(fam.std, np.sqrt(np.diag(cov)), rtol=1e-10)


def test_float32_samples_are_exactly_representable_in_float32_and_keep_the_law():
    rng = np.random.default_rng(4)
    fam = FixedCovNormal(np.full(3, 0.1), cov=np.diag([1e-6, 1.0, 4.0]))
    rounded = FixedCovNormal(
        np.full(3, 0.1), cov=np.diag([1e-6, 1.0, 4.0]), float32_samples=True
    )
    x = rounded.sample(20_000, rng)
    assert x.dtype == np.float64
    np.testing.assert_array_equal(x.astype(np.float32).astype(np.float64), x)
    y = fam.sample(5, rng)  # the unrounded family is not float32-exact
    assert not np.array_equal(y.astype(np.float32).astype(np.float64), y)
    # Same draws as the unrounded family up to float32 rounding.
    np.testing.assert_allclose(
        rounded.sample(4, np.random.default_rng(9)),
        fam.sample(4, np.random.default_rng(9)),
        rtol=1e-7,
    )
    assert rounded.project(np.ones(3)).float32_samples
    se = np.sqrt(np.diag([1e-6, 1.0, 4.0]) / len(x)).diagonal()
    assert np.all(np.abs(x.mean(0) - 0.1) < 4 * se)


def test_with_max_shift_changes_only_the_search_box():
    fam = FixedCovNormal(np.zeros(2), cov=np.eye(2), float32_samples=True)
    boxed = fam.with_max_shift([0.5, 1.0])
    np.testing.assert_array_equal(boxed.max_shift, [0.5, 1.0])
    assert fam.max_shift is None and boxed.float32_samples
    np.testing.assert_array_equal(boxed.mean, fam.mean)
    np.testing.assert_allclose(boxed.project(np.array([2.0, 2.0])).mean, [0.5, 1.0])
