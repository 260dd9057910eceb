import json

import numpy as np
import pytest
from scipy import stats

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare import (
    FixedCovNormal,
    MixtureProposal,
    get_estimator,
    mixture_ce,
)
from avrisk.rare.estimator import estimator_class
from avrisk.rare.mixture_em import (
    MERGE_DIVERGENCE,
    component_log_kernels,
    fit_mixture,
    merge_overlapping,
    seed_components,
)
from avrisk.rare.proposal_audit import audit_bound
from avrisk.testing import (
    beta_sum_problem,
    check_estimator,
    four_branch_problem,
    gaussian_linear_problem,
)
from tests.interrupts import ctrl_c_when, without_wall_time

SMALL = dict(n_per_iter=2000, n_iter=8, n_final=20_000)
ROOT2 = np.sqrt(2.0)
#: Unit directions of the four branches' design points (the curved ones at
#: distance 3, the flat ones at 3.5).
BRANCHES = np.array([[1.0, 1.0], [-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]]) / ROOT2


def mixture(problem, seed, **settings):
    return mixture_ce(
        problem.f, problem.base, problem.gamma, seed=seed, **{**SMALL, **settings}
    )


def branch_of(x):
    """Index of the branch whose direction is closest to each row of x."""
    return np.argmax(x @ BRANCHES.T, axis=1)


@pytest.mark.parametrize(
    "problem",
    [
        four_branch_problem(),
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(100, p=1e-6),
        beta_sum_problem(6, p=1e-5),
    ],
    ids=lambda p: p.name,
)
@pytest.mark.parametrize("seed", [0, 1])
def test_mixture_agrees_with_the_exact_probability_within_its_standard_error(
    problem, seed
):
    settings = dict(n_per_iter=4000) if problem.base.dim == 100 else {}
    est = check_estimator(lambda pr, s: mixture(pr, s, **settings), problem, seed=seed)
    assert est.n_hits > 100
    # relative variance per sample (naive Monte Carlo's: 1/p, 450 to 1e6 here)
    assert est.main.rel_error**2 * est.n_samples < 50


def test_the_mixture_finds_all_four_branches_and_samples_each_of_them():
    problem = four_branch_problem()
    final = []

    def keep_final(batch):
        if batch.stage == 0:
            final.append(batch)

    est = mixture_ce(
        problem.f, problem.base, problem.gamma, seed=3, on_batch=keep_final, **SMALL
    )
    means = np.array([c.mean for c in est.proposal.components])
    assert sorted(branch_of(means)) == [0, 1, 2, 3]
    # each sits on its branch beyond the design point, not between branches
    along = (means * BRANCHES[branch_of(means)]).sum(axis=1)
    across = np.linalg.norm(means - along[:, None] * BRANCHES[branch_of(means)], axis=1)
    assert (along > 2.8).all() and (across < 0.5).all()
    x = np.concatenate([b.x for b in final])
    hits = np.concatenate([b.values for b in final]) <= problem.gamma
    per_branch = np.bincount(branch_of(x[hits]), minlength=4)
    assert (per_branch > 0.05 * hits.sum()).all(), per_branch
    assert abs(est.p - problem.p_exact) < 5 * est.stderr


def test_a_single_normal_proposal_misses_branches_that_the_mixture_covers():
    problem = four_branch_problem()
    est = mixture(problem, 0, n_components=1)
    assert est.proposal.n_components == 1
    # one component covers one branch; the defensive share of P0 alone reaches
    # the others, so the standard error is several times the mixture's
    assert est.stderr > 3 * mixture(problem, 0).stderr


def test_same_seed_gives_the_same_estimate_whatever_the_batch_size():
    problem = four_branch_problem()
    runs = [
        mixture(problem, 5, n_iter=3, n_final=3001, batch_size=b)
        for b in (None, 1000, 333)
    ]
    assert len({r.p for r in runs}) == 1 and len({r.stderr for r in runs}) == 1


def test_an_interrupted_run_resumes_through_the_pipeline_to_the_uninterrupted_result(
    tmp_path,
):
    problem = four_branch_problem()
    settings = RunSettings(
        "mixture", gamma=0.0, seed=2, n_per_iter=2000, n_iter=4, n_final=10_000
    )

    def run(path, f):
        directory = RunDirectory(path, ["x0", "x1"])
        return run_estimation(directory, problem.base, f, settings)

    reference = run(tmp_path / "reference", problem.f)
    # stages 1-2 recorded, then the "machine dies"
    interrupted, _ = ctrl_c_when(problem.f, lambda sizes: len(sizes) == 2)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", interrupted)
    resumed = run(tmp_path / "run", problem.f)
    assert without_wall_time(resumed["estimate"]) == without_wall_time(
        reference["estimate"]
    )
    assert resumed["timing"]["rollouts_replayed"] == 2 * 2000
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    assert checkpoint["iterations_done"] == 4 and len(checkpoint["history"]) == 4
    proposal = checkpoint["proposal"]
    assert proposal["family"] == "Mixture" and len(proposal["components"]) == len(
        proposal["weights"]
    )
    table, audit = estimator_class("mixture").diagnostics(resumed["estimate"])
    assert len(table.rows) == 4 and audit.title.startswith("The audit")
    assert table.column("live components") == [
        h["n_components"] for h in checkpoint["history"]
    ]


def test_the_estimator_describes_its_budget_and_progress():
    estimator = get_estimator("mixture", n_per_iter=4000, n_iter=10, n_final=60_000)
    # the audit's particles: one per 50 final draws, at most 1,000
    assert estimator.budget() == 100_000 + audit_bound(1000)
    assert estimator.describe() == (
        "mixture CE (4 components) 10x4,000 + 60,000, defensive 0.1, audit 1,000"
    )
    assert get_estimator("mixture", n_final=5000).settings.audit() == 100
    est = mixture(four_branch_problem(), 0, n_iter=2, n_final=1000)
    assert estimator.progress(est.history[-1]).startswith("iter 1: gamma_k=")
    out = json.loads(json.dumps(est.to_dict()))
    assert out["proposal"]["family"] == "Mixture"
    assert out["history"][0]["n_components"] == len(out["history"][0]["weights"])


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(n_components=0), "n_components: Input should be greater than or equal"),
        (dict(rho=1.5), "rho: Input should be less than 1; got 1.5"),
        (dict(alpha=0.0), "alpha: Input should be greater than 0"),
        (dict(defensive=1.0), "defensive: Input should be less than 1"),
        (dict(min_weight=0.0), "min_weight: Input should be greater than 0"),
        (dict(select="best"), "select: Input should be 'quantile' or 'variance'"),
        (dict(n_per_iter=0), "n_per_iter: Input should be greater than or equal to 1"),
    ],
)
def test_bad_settings_are_rejected_by_name(kwargs, match):
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    with pytest.raises(ValueError, match=match):
        mixture_ce(lambda x: x[:, 0], base, 0.0, **kwargs)


def test_an_unknown_setting_is_rejected_by_name():
    with pytest.raises(ValueError, match="estimator 'mixture': select_k: Extra inputs"):
        get_estimator("mixture", select_k=2)


def two_sided():
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    left = base.project(np.array([-3.0, 0.5]))
    right = base.project(np.array([4.0, -1.0]))
    return base, left, right


def test_mixture_proposal_is_prefix_consistent_and_normalised():
    base, left, right = two_sided()
    q = MixtureProposal([left, right], [0.3, 0.7], base, defensive=0.1)
    x = q.sample(50_000, np.random.default_rng(1))
    np.testing.assert_array_equal(
        q.sample(1234, np.random.default_rng(1)), x[:1234], err_msg="row i depends on n"
    )
    # the component shares of the draws: 0.1 from P0, 0.27 and 0.63 from the others
    near_right = np.linalg.norm(x - right.mean, axis=1) < 2.0
    assert abs(near_right.mean() - 0.63 * 0.8647) < 0.01  # P(chi2_2 < 2^2)
    # E_q[p0 / q] = 1 and every weight is at most 1 / 0.1
    log_w = base.log_prob(x) - q.log_prob(x)
    w = np.exp(log_w)
    assert w.max() <= 10.0 and abs(w.mean() - 1.0) < 5 * w.std() / np.sqrt(w.size)


def test_log_prob_is_the_log_of_the_weighted_sum_of_densities():
    base, left, right = two_sided()
    q = MixtureProposal([left, right], [1.0, 3.0], base, defensive=0.2)
    x = np.random.default_rng(2).normal(size=(50, 2)) * 3
    density = (
        0.2 * np.exp(base.log_prob(x))
        + 0.8 * 0.25 * np.exp(left.log_prob(x))
        + 0.8 * 0.75 * np.exp(right.log_prob(x))
    )
    np.testing.assert_allclose(q.log_prob(x), np.log(density), rtol=1e-12)
    far = np.array([[60.0, 0.0]])  # densities underflow, the log does not
    assert np.isfinite(q.log_prob(far)).all()


def test_component_kernels_differ_from_log_densities_by_one_term_per_sample():
    problem = beta_sum_problem(3, p=1e-2)
    base = problem.base
    rng = np.random.default_rng(3)
    components = [base.project(base.mean_param() + d) for d in (-0.3, 0.0, 0.4)]
    x = base.sample(100, rng)
    kernels = component_log_kernels(components, base.sufficient_stat(x))
    densities = np.stack([c.log_prob(x) for c in components], axis=1)
    carrier = densities - kernels
    np.testing.assert_allclose(carrier, carrier[:, :1].repeat(3, axis=1), atol=1e-9)


def test_weighted_em_recovers_separated_components_and_their_weights(rng):
    base, left, right = two_sided()
    n = 4000
    x = np.where(
        (rng.random(n) < 0.25)[:, None],
        left.sample(n, rng),
        right.sample(n, rng),
    )
    # weights that tilt the data: draws near `left` count three times as much
    weights = np.where(np.linalg.norm(x - left.mean, axis=1) < 3, 3.0, 1.0)
    weights /= weights.sum()
    start, shares = seed_components(base, x, weights, 2, rng)
    fit = fit_mixture(start, shares, x, weights, min_weight=0.02)
    order = np.argsort([c.mean[0] for c in fit.components])
    means = np.array([fit.components[k].mean for k in order])
    np.testing.assert_allclose(means, [left.mean, right.mean], atol=0.1)
    np.testing.assert_allclose(fit.weights[order], [0.5, 0.5], atol=0.03)


def test_a_component_without_elites_dies_and_coinciding_components_merge(rng):
    base, left, right = two_sided()
    x = left.sample(2000, rng)
    weights = np.full(2000, 1 / 2000)
    fit = fit_mixture([left, right], np.array([0.5, 0.5]), x, weights, 0.02)
    assert len(fit.components) == 1 and list(fit.origin) == [0]
    near = base.project(left.mean + 0.5 * np.sqrt(MERGE_DIVERGENCE))
    merged, merged_weights = merge_overlapping([left, near, right], [0.2, 0.2, 0.6])
    assert len(merged) == 2 and list(merged_weights) == [0.4, 0.6]
    np.testing.assert_allclose(merged[0].mean, (left.mean + near.mean) / 2)


def test_zero_iterations_is_plain_monte_carlo():
    base = FixedCovNormal(np.zeros(1), cov=np.eye(1))
    est = mixture_ce(lambda x: x[:, 0], base, -2.0, n_iter=0, n_final=20_000, seed=1)
    assert est.ess == pytest.approx(est.n_hits, rel=1e-9)
    assert abs(est.p - stats.norm.cdf(-2.0)) < 5 * est.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    "problem",
    [four_branch_problem(), gaussian_linear_problem(2), beta_sum_problem(6)],
    ids=lambda p: p.name,
)
def test_mixture_intervals_cover_the_truth_over_repeated_seeds(problem):
    reps = 20
    covered = sum(
        est.ci[0] <= problem.p_exact <= est.ci[1]
        for est in (mixture(problem, 1000 + seed) for seed in range(reps))
    )
    # nominal 95%; fail 4 binomial standard deviations under it
    assert covered / reps >= 0.95 - 4 * np.sqrt(0.95 * 0.05 / reps)
