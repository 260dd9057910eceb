import warnings

import numpy as np
import pytest
from scipy import stats

from avrisk.rare.final_stage import (
    NEUTRAL_ADVICE,
    Advice,
    UnreliableEstimateWarning,
    ZeroHitsWarning,
    importance_estimates,
)
from avrisk.rare.intervals import clopper_pearson, normal_interval, wilson
from avrisk.rare.weights import (
    kish_ess,
    normalized_weights,
    pareto_tail_index,
    weighted_mean_and_stderr,
)


def test_weighted_mean_is_exact_for_weights_spanning_1e_minus_300_to_1e300():
    log_w = np.log(np.array([1e-300, 1e300, 1e300, 1.0]))
    hits = np.array([True, True, False, True])
    p, se = weighted_mean_and_stderr(log_w, hits)
    assert p == pytest.approx((1e-300 + 1e300 + 1.0) / 4, rel=1e-12)
    scaled_terms = np.array([1e-600, 1.0, 0.0, 1e-300])  # terms / 1e300, no overflow
    assert se == pytest.approx(1e300 * scaled_terms.std(ddof=1) / 2, rel=1e-12)


def test_weighted_mean_of_tiny_weights_does_not_underflow_to_zero():
    log_w = np.full(10, -720.0)  # exp(-720) underflows a plain float64 sum of w
    p, _ = weighted_mean_and_stderr(log_w, np.ones(10, dtype=bool))
    assert p == pytest.approx(np.exp(-720.0), rel=1e-12) and p > 0


def test_kish_ess_counts_equal_weights_and_collapses_for_one_dominant_weight():
    assert kish_ess(np.full(50, 700.0)) == pytest.approx(50.0)
    assert kish_ess(np.array([800.0, 0.0, 0.0])) == pytest.approx(1.0)
    assert kish_ess(np.array([])) == 0.0


def test_normalized_weights_sum_to_one_even_for_huge_log_weights():
    w = normalized_weights(np.array([1000.0, 1000.0 + np.log(3.0)]))
    np.testing.assert_allclose(w, [0.25, 0.75])


@pytest.mark.parametrize("k,n", [(0, 10), (3, 100), (50, 50), (7, 1_000_000)])
def test_binomial_intervals_match_scipy(k, n):
    res = stats.binomtest(k, n)
    ref_cp = res.proportion_ci(0.95, method="exact")
    ref_w = res.proportion_ci(0.95, method="wilson")
    np.testing.assert_allclose(
        clopper_pearson(k, n), (ref_cp.low, ref_cp.high), rtol=1e-9, atol=1e-15
    )
    np.testing.assert_allclose(
        wilson(k, n), (ref_w.low, ref_w.high), rtol=1e-9, atol=1e-15
    )


def test_zero_hits_give_a_positive_upper_bound_near_the_rule_of_three():
    low, high = clopper_pearson(0, 100_000)
    assert low == 0.0
    assert high == pytest.approx(1 - 0.025 ** (1 / 100_000), rel=1e-9)  # ~ 3.69 / n
    assert 3.6e-5 < high < 3.8e-5


def test_normal_interval_is_clipped_to_the_unit_interval():
    assert normal_interval(1e-6, 1e-6) == (0.0, pytest.approx(1e-6 + 1.959964e-6))


def test_interval_functions_reject_bad_levels_and_counts():
    with pytest.raises(ValueError, match="confidence level"):
        wilson(1, 10, level=1.5)
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clopper_pearson(11, 10)


def test_variance_reduction_is_undefined_for_an_estimate_outside_0_1():
    from avrisk.rare import GammaEstimate

    over = GammaEstimate(
        gamma=1.0,
        p=1.09,
        stderr=0.26,
        ci=(0.59, 1.0),
        n_hits=10,
        ess=3.0,
        n_samples=100,
    )
    assert np.isnan(over.variance_reduction)
    fine = GammaEstimate(
        gamma=1.0,
        p=0.5,
        stderr=0.01,
        ci=(0.48, 0.52),
        n_hits=50,
        ess=50.0,
        n_samples=100,
    )
    assert fine.variance_reduction == pytest.approx(0.25 / 100 / 0.01**2)


def _tail_size(n):
    return int(min(0.2 * n, 3 * np.sqrt(n)))


@pytest.mark.parametrize("k", [0.2, 0.8])
def test_pareto_tail_index_recovers_a_generalised_pareto_shape(k):
    n = 20_000
    w = stats.genpareto.rvs(k, size=n, random_state=np.random.default_rng(5))
    se = (1 + k) / np.sqrt(_tail_size(n))  # asymptotic sd of the ML shape
    got = pareto_tail_index(np.log(w) + 500.0)  # any shift of log w
    assert abs(got - k) < 3 * se


@pytest.mark.parametrize("a_q", [3.0, 8.0])
def test_pareto_tail_index_of_beta_likelihood_ratios_is_the_exact_tail(a_q):
    # Base Beta(2, 2), proposal Beta(a_q, 2): near x = 0 the weight grows as
    # x^(2 - a_q) and P(w > t) ~ t^(-a_q / (a_q - 2)), so k = (a_q - 2) / a_q:
    # 1/3 (finite variance) and 3/4 (infinite: a_q >= 2 * 2).
    n = 200_000
    x = stats.beta.rvs(a_q, 2, size=n, random_state=np.random.default_rng(6))
    log_w = stats.beta.logpdf(x, 2, 2) - stats.beta.logpdf(x, a_q, 2)
    k = (a_q - 2) / a_q
    se = (1 + k) / np.sqrt(_tail_size(n))
    assert abs(pareto_tail_index(log_w) - k) < 3 * se


def test_pareto_tail_index_needs_a_tail():
    assert np.isnan(pareto_tail_index(np.zeros(20)))  # 4 tail weights: too few
    assert pareto_tail_index(np.zeros(1000)) == -np.inf  # equal weights


def test_heavy_tailed_hit_weights_are_reported_and_warned_about():
    n = 20_000
    rng = np.random.default_rng(7)
    x = stats.beta.rvs(8.0, 2, size=n, random_state=rng)  # k = 0.75
    log_w = stats.beta.logpdf(x, 2, 2) - stats.beta.logpdf(x, 8.0, 2)
    values = rng.uniform(size=n)
    with pytest.warns(UnreliableEstimateWarning, match="Pareto k"):
        heavy = importance_estimates(values, log_w, (0.5,))[0.5]
    assert heavy.pareto_k > 0.7 and heavy.ess > 10
    assert heavy.to_dict()["pareto_k"] == heavy.pareto_k
    x = stats.beta.rvs(3.0, 2, size=n, random_state=rng)  # k = 1/3
    log_w = stats.beta.logpdf(x, 2, 2) - stats.beta.logpdf(x, 3.0, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        light = importance_estimates(values, log_w, (0.5,))[0.5]
    assert light.pareto_k < 0.5


def test_the_warnings_give_the_remedies_of_the_estimator_that_made_the_stage():
    advice = Advice("raise A", "the proposal is degenerate: raise B", "raise C")
    rng = np.random.default_rng(3)
    values = rng.uniform(size=1000)
    with pytest.warns(ZeroHitsWarning, match=r"\(0, 1\): raise A$"):
        importance_estimates(values, np.zeros(1000), (-1.0,), advice)
    values[0] = 0.0  # a hit whose weight dominates all others
    log_w = np.where(np.arange(1000) == 0, 20.0, 0.0)
    with pytest.warns(UnreliableEstimateWarning, match=r"\(the proposal is .*B\)$"):
        importance_estimates(values, log_w, (0.5,), advice)
    with pytest.warns(UnreliableEstimateWarning) as caught:
        importance_estimates(values, log_w, (0.5,))  # no estimator's: neutral
    (text,) = [str(w.message) for w in caught]
    assert NEUTRAL_ADVICE.degenerate in text and "n_per_iter" not in text


def test_only_the_main_threshold_is_warned_about_the_others_carry_it():
    values = np.random.default_rng(5).uniform(size=1000)
    values[0] = -2.0  # the one hit below -1.5: an effective number of 1
    log_w = np.zeros(1000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # gamma 0.5 is sound: no warning at all
        quiet = importance_estimates(values, log_w, (0.5, -1.5, -3.0))
    assert quiet[-1.5].n_hits == 1 and quiet[-1.5].ess == 1.0
    assert quiet[-3.0].n_hits == 0 and quiet[-3.0].ci == (0.0, 1.0)
    with pytest.warns(UnreliableEstimateWarning) as caught:
        loud = importance_estimates(values, log_w, (-1.5, -3.0, 0.5))
    (text,) = [str(w.message) for w in caught]  # -3.0's zero hits: not warned
    assert text.startswith("f <= -1.5: 1 hits but an effective number of only 1.0")
    assert loud == quiet


@pytest.mark.parametrize(
    ("method", "settings", "words"),
    [
        ("naive", dict(n_final=4000), "Clopper-Pearson"),
        ("naive", dict(n_final=4000, interval="wilson"), "Wilson"),
        ("ce", dict(rho=0.1, n_per_iter=500, n_iter=3, n_final=2000), "normal"),
        ("splitting", dict(n_particles=200), "log-normal"),
    ],
)
def test_every_estimate_names_the_interval_it_reports(method, settings, words):
    from avrisk.rare import estimate
    from avrisk.testing import gaussian_linear_problem

    problem = gaussian_linear_problem(2, p=1e-2)
    est = estimate(method, problem.f, problem.base, problem.gamma, **settings)
    assert words in est.by_gamma[problem.gamma].interval
    assert est.to_dict()["by_gamma"][0]["interval"] == est.main.interval


def test_variance_reduction_survives_a_tiny_estimate_whose_variance_underflows():
    from avrisk.rare import GammaEstimate

    tiny = GammaEstimate(0.0, 2.6e-180, 2.6e-180, (0.0, 7.8e-180), 1, 1.0, 50_000)
    assert tiny.variance_reduction == pytest.approx(1 / 50_000)
    assert tiny.to_dict()["variance_reduction"] == pytest.approx(2e-5)
