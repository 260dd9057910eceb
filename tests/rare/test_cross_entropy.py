import json
import warnings

import numpy as np
import pytest
from scipy import stats

from avrisk.rare import (
    CrossEntropy,
    EstimationContext,
    FixedCovNormal,
    NaiveMC,
    RareEventProblem,
    ScaledBeta,
    UnreliableEstimateWarning,
    ZeroHitsWarning,
    cross_entropy,
    estimate,
    mixture_ce,
    naive_mc,
)
from avrisk.rare.cross_entropy import CESettings
from avrisk.rare.estimator import get_estimator
from avrisk.rare.naive_mc import NaiveSettings
from avrisk.rare.proposal_audit import audit_bound
from avrisk.registry import UnknownComponentError
from avrisk.testing import (
    beta_sum_cdf,
    beta_sum_problem,
    check_estimator,
    gaussian_linear_problem,
    mixed_problem,
)

SMALL = dict(rho=0.1, n_per_iter=2000, n_iter=8, n_final=20_000)


def ce(problem, seed, **settings):
    return cross_entropy(
        problem.f, problem.base, problem.gamma, seed=seed, **{**SMALL, **settings}
    )


@pytest.mark.parametrize(
    "problem",
    [
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(100, p=1e-6),
        beta_sum_problem(6, p=1e-5),
        mixed_problem(1e-2, 1e-3),
    ],
    ids=lambda p: p.name,
)
@pytest.mark.parametrize("seed", [0, 1])
def test_cross_entropy_agrees_with_the_exact_probability_within_its_standard_error(
    problem, seed
):
    settings = dict(n_per_iter=4000) if problem.base.dim == 100 else {}
    est = check_estimator(lambda pr, s: ce(pr, s, **settings), problem, seed=seed)
    assert est.n_hits > 100  # importance sampling actually visits the rare event
    assert est.by_gamma[problem.gamma].variance_reduction > 100


def test_beta_sum_closed_form_agrees_with_numerical_convolution():
    from scipy import integrate

    t = 0.7
    f2 = integrate.quad(
        lambda u: stats.beta(2, 2).cdf(t - u) * stats.beta(2, 2).pdf(u), 0, t
    )[0]
    assert beta_sum_cdf(t, 2) == pytest.approx(f2, rel=1e-10)
    assert beta_sum_cdf(0.5, 1) == pytest.approx(0.5)  # symmetric Beta(2,2)
    with pytest.raises(ValueError, match="0 <= t <= 1"):
        beta_sum_cdf(1.5, 3)


def test_gamma_k_is_the_larger_of_gamma_and_the_rho_quantile():
    problem = gaussian_linear_problem(2, p=1e-6)
    est = ce(problem, 0)
    for info in est.history:
        assert info.gamma_k == max(problem.gamma, info.quantile)
        assert info.n_elite >= SMALL["rho"] * SMALL["n_per_iter"]
    assert (
        est.history[0].gamma_k > problem.gamma
    )  # the first levels are intermediate ones
    assert est.history[-1].gamma_k == problem.gamma  # and the search reaches gamma


def test_the_final_proposal_is_the_iterate_with_the_lowest_rho_quantile():
    problem = gaussian_linear_problem(2, p=1e-6)
    base, seen = problem.base, []
    rp = RareEventProblem(base, problem.f, problem.gamma)
    method = CrossEntropy(CESettings(rho=0.1, alpha=0.8, n_per_iter=1000))
    state = method.init(rp)
    for _ in range(6):
        seen.append(state.proposal)
        state, info = method.step(state, rp, EstimationContext(seed=4))
    est = cross_entropy(
        problem.f,
        base,
        problem.gamma,
        rho=0.1,
        n_per_iter=1000,
        n_iter=6,
        n_final=100,
        seed=4,
    )
    quantiles = [h.quantile for h in est.history]
    best = int(np.argmin(quantiles))
    assert est.best_iteration == best
    np.testing.assert_array_equal(est.proposal.mean, seen[best].mean)


def test_update_is_smoothed_moment_matching_of_the_weighted_elite():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    rp = RareEventProblem(base, lambda x: x[:, 0], gamma=-10.0)
    method = CrossEntropy(CESettings(rho=0.2, alpha=0.5, n_per_iter=5000))
    state, info = method.step(method.init(rp), rp, EstimationContext(seed=0))
    # the elite of N(0,1) below its 20% quantile q has mean -pdf(q)/cdf(q) = -1.40
    q = stats.norm.ppf(0.2)
    elite_mean = -stats.norm.pdf(q) / 0.2
    assert info.quantile == pytest.approx(q, abs=0.05)
    assert state.proposal.mean[0] == pytest.approx(0.5 * elite_mean, abs=0.05)


def test_estimate_counts_every_call_of_f_and_serialises_to_json():
    calls = []

    def f(x):
        calls.append(len(x))
        return 3.0 - x[:, 0]

    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    est = cross_entropy(
        f,
        base,
        0.0,
        rho=0.1,
        n_per_iter=500,
        n_iter=3,
        n_final=1000,
        batch_size=128,
        gamma_test=[0.5, -0.5],
    )
    # the search, the final stage, the audit's subset simulation after them,
    # and (X in one dimension) the check by rays
    audit = est.details["audit"]
    assert audit["particles"] == 20  # the fewest: 1,000 final draws / 50
    assert audit["reached"] and 0 < audit["n_calls"] <= audit_bound(20)
    rays = est.details["directional"]["n_calls"]
    assert est.n_evals == sum(calls) == 3 * 500 + 1000 + audit["n_calls"] + rays
    assert max(calls) <= 128
    out = json.loads(json.dumps(est.to_dict()))
    assert [g["gamma"] for g in out["by_gamma"]] == [0.0, 0.5, -0.5]
    assert len(out["history"]) == 3 and out["proposal"]["family"] == "FixedCovNormal"


def test_same_seed_gives_the_same_estimate_whatever_the_batch_size():
    problem = beta_sum_problem(6, p=1e-5)
    runs = [
        ce(problem, 5, n_iter=3, n_final=3001, batch_size=b) for b in (None, 1000, 333)
    ]
    assert len({r.p for r in runs}) == 1 and len({r.stderr for r in runs}) == 1


def test_seeded_functions_get_per_sample_seeds_independent_of_batching():
    class NoisyLimitState:
        needs_seeds = True

        def __call__(self, x, seeds):
            noise = np.array([np.random.default_rng(s).normal() for s in seeds])
            return 4.0 - x[:, 0] + 0.3 * noise

    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    runs = [
        cross_entropy(
            NoisyLimitState(),
            base,
            0.0,
            rho=0.1,
            n_per_iter=500,
            n_iter=4,
            n_final=2000,
            batch_size=b,
        )
        for b in (None, 7)
    ]
    assert runs[0].p == runs[1].p
    p_true = stats.norm.sf(4.0 / np.sqrt(1 + 0.3**2))
    assert abs(runs[0].p - p_true) < 5 * runs[0].stderr


def test_zero_final_hits_warn_and_report_an_uninformative_interval():
    base = ScaledBeta(2.0, 2.0)
    with pytest.warns(ZeroHitsWarning, match="no sample of the final stage"):
        est = cross_entropy(lambda x: x[:, 0], base, -1.0, n_iter=0, n_final=100)
    assert est.p == 0.0 and est.ci == (0.0, 1.0)


def test_zero_iterations_is_plain_monte_carlo_with_unit_weights():
    base = ScaledBeta(2.0, 2.0)
    est = cross_entropy(lambda x: x[:, 0], base, 0.3, n_iter=0, n_final=10_000, seed=1)
    assert est.ess == pytest.approx(est.n_hits, rel=1e-12)  # all weights are one
    assert abs(est.p - stats.beta(2, 2).cdf(0.3)) < 5 * est.stderr


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(rho=0.0), "rho: Input should be greater than 0; got 0.0"),
        (dict(rho=1.5), "rho: Input should be less than 1; got 1.5"),
        (dict(alpha=0.0), "alpha: Input should be greater than 0"),
        (dict(n_per_iter=0), "n_per_iter: Input should be greater than or equal to 1"),
        (dict(n_iter=-1), "n_iter: Input should be greater than or equal to 0"),
        (dict(n_final=2.5), "n_final"),
        (dict(gamma_test=[np.nan]), "gamma_test"),
    ],
)
def test_bad_settings_are_rejected_by_name(kwargs, match):
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(ValueError, match=match):
        cross_entropy(lambda x: x[:, 0], base, 0.0, **kwargs)


def test_a_nan_threshold_is_rejected():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(ValueError, match="gamma must be a finite number"):
        cross_entropy(lambda x: x[:, 0], base, float("nan"))


@pytest.mark.slow
@pytest.mark.parametrize(
    "problem",
    [gaussian_linear_problem(2, p=1e-6), beta_sum_problem(6, p=1e-5)],
    ids=lambda p: p.name,
)
def test_cross_entropy_intervals_cover_the_truth_over_repeated_seeds(problem):
    reps = 200
    covered = 0
    for seed in range(reps):
        est = ce(problem, 1000 + seed, n_per_iter=1000, n_iter=8, n_final=5000)
        covered += est.ci[0] <= problem.p_exact <= est.ci[1]
    # nominal 95%; fail 4 binomial standard deviations under it (~1e-4 false failures)
    assert covered / reps >= 0.95 - 4 * np.sqrt(0.95 * 0.05 / reps)


@pytest.mark.slow
def test_cross_entropy_is_unbiased_over_repeated_seeds_in_dimension_100():
    problem = gaussian_linear_problem(100, p=1e-6)
    ests = np.array(
        [
            ce(problem, 2000 + s, n_per_iter=3000, n_iter=8, n_final=10_000).p
            for s in range(30)
        ]
    )
    se_of_mean = ests.std(ddof=1) / np.sqrt(len(ests))
    assert abs(ests.mean() - problem.p_exact) < 4 * se_of_mean


def test_a_degenerate_proposal_warns_that_its_standard_error_is_unreliable():
    # 80 elites in 100 dimensions: the lowest-quantile iterate overshoots and its
    # weights collapse onto a few samples
    problem = gaussian_linear_problem(100, p=1e-6)
    with pytest.warns(UnreliableEstimateWarning, match="effective number of only"):
        est = ce(problem, 0, rho=0.1, n_per_iter=800, n_iter=8, n_final=13_600)
    assert est.ess < 10 < est.n_hits


def test_variance_selection_picks_the_eligible_iterate_with_the_lowest_rel_var():
    problem = gaussian_linear_problem(2, p=1e-6)
    est = ce(problem, 1, select="variance")
    chosen = est.history[est.best_iteration]
    eligible = [h.rel_var for h in est.history if h.n_hits >= 10]
    assert chosen.n_hits >= 10 and chosen.rel_var == min(eligible)
    assert abs(est.p - problem.p_exact) < 5 * est.stderr


@pytest.mark.slow
def test_variance_selection_errs_less_than_the_quantile_rule_when_elites_are_few():
    # 80 elites in 100 dimensions: the lowest-quantile iterate overshoots with
    # collapsed weights (measured median |rel. error| over 12 seeds: 0.69 for the
    # quantile rule, 0.17 for the variance rule; neither is trustworthy here)
    problem = gaussian_linear_problem(100, p=1e-6)
    settings = dict(rho=0.1, n_per_iter=800, n_iter=8, n_final=13_600)
    errors = {"quantile": [], "variance": []}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnreliableEstimateWarning)
        for seed in range(6):
            for rule, errs in errors.items():
                est = ce(problem, seed, select=rule, **settings)
                errs.append(abs(est.p / problem.p_exact - 1))
    assert np.median(errors["variance"]) < np.median(errors["quantile"])


def test_rel_var_predicts_the_final_relative_standard_error():
    problem = beta_sum_problem(6, p=1e-5)
    est = ce(problem, 2, n_iter=8, n_final=40_000)
    predicted = np.sqrt(est.history[est.best_iteration].rel_var / est.n_samples)
    assert 0.5 < est.main.rel_error / predicted < 2.0


def test_an_unknown_selection_rule_is_rejected_by_name():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(
        ValueError, match="select: Input should be 'quantile' or 'variance'"
    ):
        cross_entropy(lambda x: x[:, 0], base, 0.0, select="best")


def test_a_settings_object_and_its_overrides_give_the_run_of_the_keywords():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))

    def run(**kwargs):
        est = cross_entropy(lambda x: x[:, 0], base, -2.0, seed=1, **kwargs)
        return {**est.to_dict(), "wall_time_s": None}

    settings = CESettings(rho=0.1, n_per_iter=200, n_iter=5, n_final=500)
    assert run(settings=settings, n_iter=2) == run(
        rho=0.1, n_per_iter=200, n_iter=2, n_final=500
    )


@pytest.mark.parametrize("method", ["ce", "mixture", "splitting"])
def test_a_keyword_that_is_no_setting_is_a_type_error_naming_it(method):
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(TypeError, match=r"estimate\(\) got .* keyword .* 'n_iters'"):
        estimate(method, lambda x: x[:, 0], base, 0.0, n_iters=3)
    with pytest.raises(TypeError, match=r"estimate\(\) takes settings of"):
        estimate(method, lambda x: x[:, 0], base, 0.0, settings=NaiveSettings())


def test_a_method_given_as_an_estimator_takes_no_settings_beside_it():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    built = get_estimator("naive", n_final=500)
    with pytest.raises(TypeError, match="not with an estimator built already"):
        estimate(built, lambda x: x[:, 0], base, 0.0, n_final=600)
    by_name = estimate("naive", lambda x: x[:, 0], base, -1.0, n_final=500, seed=2)
    by_object = estimate(built, lambda x: x[:, 0], base, -1.0, seed=2)
    assert by_object.by_gamma == by_name.by_gamma


def test_an_unknown_method_lists_the_registered_ones():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(UnknownComponentError, match="known: ce, defensive, mixture"):
        estimate("cee", lambda x: x[:, 0], base, 0.0)


@pytest.mark.filterwarnings("ignore::avrisk.rare.UnreliableEstimateWarning")
@pytest.mark.parametrize("search", [cross_entropy, mixture_ce], ids=["ce", "mixture"])
@pytest.mark.parametrize(
    "problem", [gaussian_linear_problem(2, p=1e-6), beta_sum_problem(6, p=1e-5)]
)
def test_a_search_long_enough_converges_and_a_short_one_says_it_did_not(
    search, problem
):
    """rho 0.1 lowers the level about tenfold per iteration: ~6 to reach 1e-6."""
    runs = {}
    for n_iter in (8, 3):
        est = search(
            problem.f, problem.base, problem.gamma, seed=0, rho=0.1,
            n_per_iter=2000, n_iter=n_iter, n_final=2000,
        )  # fmt: skip
        record = json.loads(json.dumps(est.to_dict()))  # as a summary holds it
        quantiles = [h.quantile for h in est.history]
        runs[n_iter] = (CrossEntropy.convergence(record, problem.gamma), quantiles)
    (long, quantiles), (short, short_quantiles) = runs[8], runs[3]
    first = next(k for k, q in enumerate(quantiles) if q <= problem.gamma)
    assert long.converged and long.reached_at == first and 2 <= first < 7
    assert long.n_iter == 8 and long.last == quantiles[-1] <= problem.gamma
    assert long.sentence() == (
        f"the search reached f <= {problem.gamma:g} after {first + 1} of its 8 "
        "iterations and held it (converged)"
    )
    assert not short.converged and short.reached_at is None
    assert short.lowest == min(short_quantiles) > problem.gamma
    assert short.sentence().startswith(
        f"the search did not reach f <= {problem.gamma:g}: its lowest rho-quantile "
        f"of f in 3 iterations was {min(short_quantiles):.3g}"
    )
    assert short.to_dict()["converged"] is False


def test_a_search_that_left_gamma_again_has_not_converged():
    history = [{"quantile": q} for q in (3.0, 0.8, 1.4)]
    search = CrossEntropy.convergence({"history": history}, 1.0)
    assert search.reached_at == 1 and search.last == 1.4 and not search.converged
    assert search.sentence().startswith(
        "the search reached f <= 1 after 2 of its 3 iterations but its last "
        "iteration's rho-quantile of f was back at 1.4"
    )
    # the same search at a threshold it never left, and at one it never reached
    assert CrossEntropy.convergence({"history": history}, 1.5).converged
    assert CrossEntropy.convergence({"history": history}, 0.5).reached_at is None


def test_without_iterations_or_a_search_there_is_no_convergence_to_judge():
    est = cross_entropy(
        lambda x: x[:, 0], ScaledBeta(2.0, 2.0), 0.3, n_iter=0, n_final=100
    )
    assert CrossEntropy.convergence(est.to_dict(), 0.3) is None
    naive = naive_mc(lambda x: x[:, 0], ScaledBeta(2.0, 2.0), 0.3, 100)
    assert NaiveMC.convergence(naive.to_dict(), 0.3) is None
