"""The check by rays (directional simulation) of a search in low dimension."""

import numpy as np
from scipy import stats

from avrisk.rare.directional_audit import (
    MAX_DIM,
    RADII,
    RAYS,
    _radii,
    _ray_probabilities,
    audit_calls,
    directional_audit,
)
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import estimator_class, get_estimator, run_estimator
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate, GammaEstimate
from avrisk.rare.trust import estimate_diagnostics, estimate_trust
from avrisk.testing.suite import suite_problem

#: Two regions holding 99.1% and 0.9% of p in d = 2; levels often keep only
#: the small one (BENCHMARKS.md, "The exact suite").
RP110 = suite_problem("RP110")


def rare(problem):
    return RareEventProblem(problem.base, problem.f, problem.gamma)


def made_up(p, ci, gamma=0.0):
    """An estimator's estimate with only what the check reads: p and its interval."""
    at = GammaEstimate(
        gamma=gamma, p=p, stderr=0.0, ci=ci, n_hits=100, ess=100.0, n_samples=1000
    )
    return Estimate(method="made up", gamma=gamma, by_gamma={gamma: at}, n_evals=0)


def test_along_a_ray_the_probability_is_the_chi_square_tail_past_the_crossing():
    # f(z) = beta - z_1: a ray a crosses at beta / a_1 where a_1 > 0, and f is
    # linear along it, so the interpolated crossing is exact
    beta, dim = 3.0, 3
    rng = np.random.default_rng(0)
    a = rng.standard_normal((200, dim))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    radii = _radii(dim)
    margin = beta - radii[None, :] * a[:, :1]
    exact = np.where(a[:, 0] > 0, stats.chi2.sf((beta / a[:, 0]) ** 2, dim), 0.0)
    reachable = beta / np.maximum(a[:, 0], 1e-300) <= radii[-1]
    got = _ray_probabilities(margin, radii, dim)
    np.testing.assert_allclose(got[reachable], exact[reachable], rtol=1e-9, atol=0)
    # a ray that starts in the event and leaves it counts the ball inside
    inside = _ray_probabilities((radii - 2.0)[None, :], radii, dim)
    assert inside[0] == stats.chi2.cdf(4.0, dim)


def test_the_rays_estimate_p_without_bias_and_their_low_end_stays_below_it():
    problem = suite_problem("kregions_k1_d2_p1e-03")  # one half-space, p = 1e-3
    fake = made_up(problem.p_exact, (0.9 * problem.p_exact, 1.1 * problem.p_exact))
    records = [
        directional_audit(rare(problem), EstimationContext(seed=s), fake)
        for s in range(40)
    ]
    p = np.array([r["p"] for r in records])
    spread = p.std(ddof=1) / np.sqrt(len(p))
    assert abs(p.mean() - problem.p_exact) < 3 * spread
    # each record's own standard error is the spread's, as a mean's should be
    stderr = np.median([r["stderr"] for r in records])
    assert 0.7 < stderr / p.std(ddof=1) < 1.4
    assert sum(r["low"] > problem.p_exact for r in records) <= 2
    assert not any(r["doubt"] for r in records)
    assert all(r["n_calls"] == RAYS * RADII for r in records)


def test_the_rays_doubt_an_interval_far_below_p_and_not_one_that_holds_it():
    problem, context = rare(RP110), EstimationContext(seed=0)
    p = RP110.p_exact
    low = directional_audit(problem, context, made_up(0.01 * p, (0.009 * p, 0.011 * p)))
    fair = directional_audit(problem, context, made_up(p, (0.9 * p, 1.1 * p)))
    assert low["doubt"] and not fair["doubt"]
    assert (low["p"], low["low"]) == (fair["p"], fair["low"])  # same seed, same rays
    assert low["low"] > 0.3 * p and low["rays_in_event"] > 50


def test_a_run_whose_levels_lost_the_large_region_says_caution():
    method = "splitting"
    estimator = get_estimator(method, n_particles=600)
    est = run_estimator(estimator, rare(RP110), EstimationContext(seed=0))
    assert est.ci[1] < 0.1 * RP110.p_exact  # its levels kept the small region only
    record = est.details["directional"]
    assert record["doubt"] and record["low"] > est.ci[1]
    summary = est.to_dict()
    trust = estimate_trust(estimator_class(method), summary, summary["by_gamma"][0])
    assert any("random rays" in reason for reason in trust.reasons)
    # the reports show it as a table after the estimator's own
    table = estimate_diagnostics(estimator_class(method), summary)[-1]
    assert table.title.startswith("Rays") and table.rows[0][-1] == "caution"


def test_the_rays_add_their_calls_and_leave_the_estimate_as_it_was():
    estimator = get_estimator("splitting", n_particles=600)
    problem, context = rare(RP110), EstimationContext(seed=1)
    state = estimator.init(problem)
    while not estimator.done(state):
        state, _ = estimator.step(state, problem, context)
    alone = estimator.finalize(state, problem, context)
    checked = run_estimator(estimator, problem, context)
    assert checked.by_gamma == alone.by_gamma
    assert checked.n_evals == alone.n_evals + RAYS * RADII
    assert "directional" not in (alone.details or {})


def test_the_rays_run_only_for_searches_in_low_dimension():
    splitting, naive = get_estimator("splitting"), get_estimator("naive")
    assert audit_calls(splitting, MAX_DIM) == RAYS * RADII
    assert audit_calls(splitting, MAX_DIM + 1) == 0
    assert audit_calls(naive, 2) == 0  # no search, no region left out
    wide = suite_problem(f"kregions_k1_d{MAX_DIM + 1}_p1e-03")
    est = run_estimator(
        get_estimator("splitting", n_particles=500), rare(wide), EstimationContext()
    )
    assert "directional" not in (est.details or {})
    small = suite_problem("kregions_k1_d2_p1e-03")
    est = run_estimator(
        get_estimator("naive", n_final=1000), rare(small), EstimationContext()
    )
    assert est.n_evals == 1000 and "directional" not in (est.details or {})


def test_points_far_out_where_f_fails_count_safe_and_never_stop_the_run():
    problem = suite_problem("kregions_k1_d2_p1e-03")

    def f(x):  # fails beyond radius 5 of P0's centre, as a simulator may
        bad = np.linalg.norm(x, axis=1) > 5.0
        return {"f": np.where(bad, np.nan, problem.f(x)), "status": bad.astype(np.int8)}

    est = run_estimator(
        get_estimator("splitting", n_particles=500),
        RareEventProblem(problem.base, f, problem.gamma),
        EstimationContext(seed=2),
    )
    record = est.details["directional"]
    assert record["n_failed"] > 0.2 * record["n_calls"]  # far above the run's 1%
    assert not record["doubt"] and 0 < record["p"] < 2 * problem.p_exact
