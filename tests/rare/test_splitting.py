"""Subset simulation: exact problems, ties, errors, seeds, resume, diagnostics."""

import json

import numpy as np
import pytest
from scipy import stats

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare import (
    EstimationContext,
    FixedCovNormal,
    SplittingError,
    get_estimator,
    run_estimator,
    subset_simulation,
)
from avrisk.rare.directional_audit import audit_calls
from avrisk.rare.estimator import estimator_class
from avrisk.rare.problem import SAMPLE_CHUNK, RareEventProblem
from avrisk.rare.splitting import SubsetSimulation
from avrisk.rare.splitting_levels import (
    ParticleSet,
    chain_correlation,
    level_cov_squared,
    lognormal_interval,
    next_level,
)
from avrisk.rare.splitting_moves import (
    CORRELATED,
    MAX_ROUNDS_WITHOUT_MOVE,
    MovedSet,
    moves_after,
    refreshed,
)
from avrisk.rare.splitting_settings import SplittingSettings
from avrisk.rare.trust import estimate_trust
from avrisk.testing import (
    beta_sum_problem,
    check_estimator,
    four_branch_problem,
    gaussian_linear_problem,
)
from avrisk.testing.generated import decoy_problem
from tests.interrupts import ctrl_c_when, without_wall_time

NORMAL_1D = FixedCovNormal(np.zeros(1), cov=np.eye(1))


#: One replicate's levels, never regrown: the mechanics the tests below check
#: (the replicates have tests of their own, and so has the check by rays that
#: a run adds in low dimension, tests/rare/test_directional_audit.py).
ONE = {"replicates": 1, "regrow": 0, "directional_audit": False}


def one_replicate(f, base, gamma, **kw):
    return subset_simulation(f, base, gamma, **{**ONE, **kw})


def sus(problem, seed=0, **kw):
    return one_replicate(problem.f, problem.base, problem.gamma, seed=seed, **kw)


def without_clock(estimate):
    return estimate.to_dict() | {"wall_time_s": 0}


@pytest.mark.parametrize(
    "problem",
    [
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(100, p=1e-6),
        beta_sum_problem(6, p=1e-5),
        four_branch_problem(),
    ],
    ids=lambda p: p.name,
)
def test_subset_simulation_finds_p_of_exact_problems_within_its_stderr(problem):
    est = check_estimator(sus, problem, seed=4)
    levels = est.details["levels"]
    assert levels[-1] == problem.gamma and np.all(np.diff(levels) < 0)
    assert len(levels) == len(est.history)
    survivors = est.details["survivors"]
    n = est.details["n_particles"]
    product = np.prod(np.array(survivors, dtype=float) / n)  # counts, not p0^L
    bias = 1 + np.sum(np.square(est.details["level_cov"][:-1]))
    assert est.p == pytest.approx(product / bias, rel=1e-12)
    assert survivors[-1] == est.n_hits
    au_beck = lognormal_interval(est.p, np.sum(np.square(est.details["level_cov"])))
    # the family tree's interval where it is wider
    assert est.ci[0] <= au_beck[0] * (1 + 1e-12) and est.ci[1] >= au_beck[1] * (
        1 - 1e-12
    )
    assert est.n_evals == est.history[-1].n_evals < n * len(levels)
    assert est.details["n_failed"] == 0


def test_pcn_mixes_as_well_in_100_dimensions_as_in_2():
    by_dim = {}
    for dim in (2, 100):
        est = sus(gaussian_linear_problem(dim, p=1e-6), seed=1)
        moved = est.history[1:]
        by_dim[dim] = (
            np.array([h.acceptance for h in moved]),
            np.array([h.cov for h in moved]),
        )
    for acceptance, _ in by_dim.values():
        assert ((0.2 < acceptance) & (acceptance < 0.45)).all(), acceptance
    # a level's c.o.v. carries the chains' correlation: it must not grow with D
    assert by_dim[100][1].mean() < 1.25 * by_dim[2][1].mean()


@pytest.mark.slow
def test_the_95_percent_interval_covers_p_in_most_runs():
    problems = [
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(100, p=1e-6),
        beta_sum_problem(6, p=1e-5),
        four_branch_problem(),
    ]
    covered = {}
    for problem in problems:
        runs = [sus(problem, seed=100 + s, n_particles=1000) for s in range(20)]
        covered[problem.name] = np.mean(
            [lo <= problem.p_exact <= hi for lo, hi in (e.ci for e in runs)]
        )
    assert np.mean(list(covered.values())) >= 0.85, covered
    assert min(covered.values()) >= 0.7, covered


def test_few_particles_per_level_run_high_without_the_bias_correction():
    # 300 particles and five levels set by the particles: the product runs
    # about 40% high (Cerou et al. 2012's n0 (1 - p0) / (N p0), and the chains'
    # correlation); divided by 1 + sum of the levels' delta^2, it does not
    problem = gaussian_linear_problem(2, p=1e-6)
    runs = [sus(problem, seed=s, n_particles=300) for s in range(200)]
    corrected = np.array([e.p for e in runs]) / problem.p_exact
    bias = [1 + np.sum(np.square(e.details["level_cov"][:-1])) for e in runs]
    product = corrected * np.array(bias)
    se = corrected.std(ddof=1) / np.sqrt(len(runs))
    assert abs(corrected.mean() - 1) < 3 * se, (corrected.mean(), se)
    assert product.mean() - 1 > 3 * product.std(ddof=1) / np.sqrt(len(runs))


def test_same_seed_same_result_whatever_the_batch_size():
    problem = four_branch_problem()
    whole = sus(problem, seed=3, n_particles=500)
    batched = sus(problem, seed=3, n_particles=500, batch_size=37)
    assert without_clock(batched) == without_clock(whole)
    assert without_clock(sus(problem, seed=4, n_particles=500)) != without_clock(whole)


def test_a_level_larger_than_a_chunk_goes_out_in_chunks_with_distinct_seeds():
    problem = gaussian_linear_problem(2, p=1e-3)
    seeded_calls = []

    def f(x, seeds):
        seeded_calls.append(seeds)
        return problem.f(x)

    f.needs_seeds = True
    batches = []
    est = one_replicate(
        f,
        problem.base,
        problem.gamma,
        n_particles=SAMPLE_CHUNK + 100,
        on_batch=batches.append,
    )
    keys = [(b.stage, b.chunk) for b in batches]
    assert len(set(keys)) == len(keys)
    assert max(len(b.values) for b in batches) == SAMPLE_CHUNK
    assert sum(len(b.values) for b in batches) == est.n_evals
    seeds = np.concatenate(seeded_calls)
    assert len(np.unique(seeds)) == len(seeds) == est.n_evals  # a fresh seed each
    assert abs(est.p - problem.p_exact) < 5 * est.stderr


def test_a_seeded_f_interrupted_mid_level_resumes_to_the_same_summary(tmp_path):
    problem = gaussian_linear_problem(2, p=1e-4)
    settings = RunSettings("splitting", gamma=0.0, seed=2, n_particles=500)

    def noisy(x, seeds):  # a stochastic f: its outcome depends on the seed too
        return problem.f(x) + 0.1 * (seeds % 1000) / 1000

    noisy.needs_seeds = True

    def run(path, f=noisy):
        directory = RunDirectory(path, ["x0", "x1"])
        return run_estimation(directory, problem.base, f, settings)

    reference = run(tmp_path / "reference")
    # P0, then 9 rounds of level 1 and 4 of level 2
    interrupted, calls = ctrl_c_when(noisy, lambda sizes: len(sizes) == 14)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", f=interrupted)
    resumed = run(tmp_path / "run")
    assert resumed["method"] == "splitting"
    assert without_wall_time(resumed["estimate"]) == without_wall_time(
        reference["estimate"]
    )
    assert resumed["timing"]["rollouts_replayed"] == sum(calls)


def test_a_coarse_f_with_ties_still_reaches_gamma_and_finds_p():
    # f = floor(2 x): ties at every half-integer of x; P(f <= -6) = Phi(-2.5)
    est = one_replicate(
        lambda x: np.floor(2 * x[:, 0]), NORMAL_1D, -6.0, n_particles=2000, seed=1
    )
    levels = est.details["levels"]
    assert levels[-1] == -6.0 and all(level == int(level) for level in levels)
    # a tied level keeps more survivors than p0 N: they are counted, not assumed
    assert max(est.details["survivors"][:-1]) > 200
    assert abs(est.p - stats.norm.cdf(-2.5)) < 5 * est.stderr


def test_a_mostly_infinite_f_starts_below_the_ties_at_infinity():
    # f is inf (no encounter) for 93% of P0; P(f <= 0) = P(x <= -4) = Phi(-4)
    def f(x):
        return np.where(x[:, 0] < -1.5, 4.0 + x[:, 0], np.inf)

    est = one_replicate(f, NORMAL_1D, 0.0, n_particles=2000, seed=2)
    first = est.history[0]
    assert np.isfinite(first.level) and first.n_survivors < 0.1 * 2000
    assert abs(est.p - stats.norm.cdf(-4.0)) < 5 * est.stderr


@pytest.mark.parametrize(
    ("values", "current", "p0_max", "expected"),
    [
        ([0, 1, 1, 1, 1, 2, 3, 4, 5, 6], np.inf, 0.5, 1.0),  # 5 tied survivors: kept
        ([0, 1, 1, 1, 1, 2, 3, 4, 5, 6], np.inf, 0.4, 0.0),  # too many: go below
        ([1, 1, 1, 1, 1, 2, 3, 4, 5, 6], np.inf, 0.4, 1.0),  # nothing below: keep
        ([1, 1, 1, 1, 1, 2, 3, 3, 3, 3], 3.0, 0.4, 1.0),  # still below the current
        ([-2, 1, 1, 1, 1, 2, 3, 4, 5, 6], np.inf, 0.4, -1.0),  # below gamma: gamma
        ([0, 1, 2, 3, 4, 5, 6, np.inf, np.inf, np.inf], np.inf, 0.5, 1.0),
    ],
)
def test_next_level_is_the_quantile_or_the_value_below_its_ties(
    values, current, p0_max, expected
):
    level = next_level(np.array(values, dtype=float), current, -1.0, 0.2, p0_max)
    assert level == expected


@pytest.mark.parametrize(
    ("values", "current"), [([3.0] * 10, 3.0), ([np.inf] * 10, np.inf)]
)
def test_next_level_finds_none_below_a_set_flat_at_the_current_level(values, current):
    assert next_level(np.array(values), current, -1.0, 0.1, 0.5) is None


def plateau_f(share: float, cap: float = 5.0, p_below: float = 1e-2):
    """``f`` tied at ``cap`` on all but ``share`` of P0 (2-d normal), and its exact p.

    Off the plateau (``x_1 >= t``, ``P0 = share``) ``f = min(cap, b - x_0)``;
    ``P0(f <= 0) = share * P(x_0 >= b) = share * p_below``.
    """
    t, b = stats.norm.isf(share), stats.norm.isf(p_below)

    def f(x):
        return np.where(x[:, 1] >= t, np.minimum(cap, b - x[:, 0]), cap)

    return f, share * p_below


def zero_hit_bound(n: int) -> float:
    """Exact (Clopper-Pearson) 95% upper bound of a share of 0 in ``n``."""
    return -np.expm1(np.log(0.025) / n)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_plateau_of_f_grows_the_first_set_and_the_levels_go_on(seed):
    # 99.9% of P0 ties at f = 5 (a capped TTC): 1,000 draws hold one below it
    # on average; the first set grows to 8,000 and the estimate covers p
    f, p = plateau_f(1e-3)
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    est = one_replicate(f, base, 0.0, n_particles=1000, seed=seed)
    assert est.details["first_set_draws"] == 8000
    assert not est.details["bound_only"]
    assert est.ci[0] < p < est.ci[1]


def test_a_plateau_nothing_leaves_gives_an_honest_bound_not_an_error():
    # floor(2 x) but never below -3: the chains at f = -3 cannot go lower
    def f(x):
        return np.maximum(np.floor(2 * x[:, 0]), -3.0)

    est = one_replicate(f, NORMAL_1D, -5.0, n_particles=500)
    assert est.p == 0.0 and est.details["bound_only"]
    # the share of the draws at f <= -3 (its upper end) times the bound of 0
    # in 500 states
    first = est.details["survivors"][0] / 500
    assert abs(first - stats.norm.cdf(-1.0)) < 0.05
    assert est.ci[0] == 0.0
    assert first * zero_hit_bound(500) < est.ci[1] < 1.5 * first * zero_hit_bound(500)
    # an f infinite everywhere: the first set grows, then a bound from the
    # 3,500 draws after the first 500
    est = one_replicate(
        lambda x: np.full(len(x), np.inf), NORMAL_1D, 0.0, n_particles=500
    )
    assert est.p == 0.0 and est.details["first_set_draws"] == est.n_evals == 4000
    assert est.ci == (0.0, pytest.approx(zero_hit_bound(3500)))


def test_an_event_out_of_reach_of_the_levels_is_naive_samplings_bound_with_caution():
    # f >= 10 everywhere: the levels creep towards 10 and never reach gamma = 5
    def f(x):
        return 10.0 + x[:, 0] ** 2

    est = one_replicate(f, NORMAL_1D, 5.0, n_particles=500, max_levels=4)
    assert est.p == 0.0 and est.details["bound_only"]
    assert est.details["replicates_exhausted"] == 1 and len(est.details["levels"]) == 1
    # the first set's 500 draws of P0, none at or below gamma: naive's exact bound
    assert est.ci == (0.0, pytest.approx(zero_hit_bound(500)))
    as_dict = est.to_dict()
    label = estimate_trust(
        estimator_class("splitting"), as_dict, as_dict["by_gamma"][0]
    )
    assert label.word == "caution"
    assert "1 of the 1 replicates of the search did not reach gamma" in str(label)
    assert "naive sampling's of their first draws of P0" in str(label)


def test_chains_that_never_move_are_an_error_once_their_step_is_smallest():
    calls = []

    def f(x):  # finite on the draws of P0 only: every proposal is rejected
        calls.append(len(x))
        return x[:, 0] if len(calls) == 1 else np.full(len(x), np.inf)

    with pytest.raises(SplittingError, match="no chain accepted.*smallest step"):
        one_replicate(f, NORMAL_1D, -5.0, n_particles=500)
    # beta falls from 0.6 by exp(-0.3) a round to 1e-3, then 10 more rounds
    assert MAX_ROUNDS_WITHOUT_MOVE < len(calls) - 1 < 50


def test_a_single_chain_that_is_refused_a_while_goes_on():
    # two chains in a thin region: runs of rejections are common, not fatal
    f, p = plateau_f(1e-3)
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    est = one_replicate(f, base, 0.0, n_particles=1000, seed=1, plateau_draws=2)
    assert est.details["first_set_draws"] == 2000
    assert est.details["survivors"][0] == 2 and est.ci[0] < p < est.ci[1]


def test_failed_evaluations_count_as_outside_the_level_and_are_reported():
    problem = gaussian_linear_problem(2, p=1e-4)

    def f(x):  # about 1 in 1,000 evaluations fails, wherever it is
        bad = np.abs(np.sin(1e4 * x[:, 0])) < 5e-4 * np.pi
        return {
            "f": np.where(bad, np.nan, problem.f(x)),
            "status": bad.astype(np.int8),
        }

    batches = []
    with pytest.warns(UserWarning, match="evaluations of f failed"):
        est = one_replicate(
            f, problem.base, 0.0, n_particles=2000, seed=1, on_batch=batches.append
        )
    n_failed = sum(int(np.count_nonzero(b.failed)) for b in batches)
    assert est.details["n_failed"] == n_failed > 0
    assert abs(est.p - problem.p_exact) < 5 * est.stderr


def test_test_thresholds_come_from_the_deepest_level_that_holds_them():
    problem = gaussian_linear_problem(2, p=1e-4)
    beta = stats.norm.isf(problem.p_exact)
    est = one_replicate(
        problem.f,
        problem.base,
        0.0,
        gamma_test=(2.0, 1.0, -0.3, -4.0),
        n_particles=2000,
        seed=5,
    )
    for g in (2.0, 1.0, -0.3):
        part = est.by_gamma[g]
        assert abs(part.p - stats.norm.sf(beta - g)) < 5 * part.stderr
        assert part.ci[0] < part.p < part.ci[1]
    unseen = est.by_gamma[-4.0]  # below every particle: bounded by gamma's interval
    assert unseen.p == unseen.n_hits == 0 and 0.0 == unseen.ci[0] < unseen.ci[1]
    assert unseen.ci[1] <= est.ci[1]


def test_the_au_beck_cov_grows_with_correlation_along_the_chains():
    independent = np.arange(100.0).reshape(100, 1)  # 100 chains of one state
    assert level_cov_squared(independent, 9.5) == pytest.approx(0.9 / (100 * 0.1))
    chained = np.repeat(np.arange(10.0), 10).reshape(10, 10)  # chains stuck in place
    # every chain is all in or all out: 10 states count as 1 (1 + gamma_l = 10)
    assert level_cov_squared(chained, 0.5) == pytest.approx(0.9 / (100 * 0.1) * 10)
    padded = np.array([[0.0, 1.0, 2.0], [3.0, 4.0, np.nan]])  # 5 states in all
    assert level_cov_squared(padded, 10.0) == 0.0  # every particle below: p = 1


def test_settings_are_validated_by_name():
    with pytest.raises(ValueError, match=r"p0_max \(0.05\) must be at least p0"):
        get_estimator("splitting", p0=0.1, p0_max=0.05)
    with pytest.raises(ValueError, match="n_moves"):
        get_estimator("splitting", n_moves=0)
    assert SplittingSettings().recorded()["n_particles"] == 2000


def test_protocol_budget_progress_checkpoint_and_diagnostics():
    method = get_estimator(
        "splitting", n_particles=400, max_levels=6, n_moves=2, replicates=1, regrow=0
    )
    assert method.budget() == 400 * (8 + 5 * 2)  # 8 N draws on a plateau
    assert method.describe() == (
        "subset simulation, 400 particles per level, p0 0.1, 2 moves per state"
    )
    problem = gaussian_linear_problem(2, p=1e-4)
    rp = RareEventProblem(problem.base, problem.f, problem.gamma)
    steps = []
    est = run_estimator(
        method, rp, EstimationContext(seed=3), callback=lambda i, s: steps.append(s)
    )
    # its own calls within its budget, and the rays a run adds in low dimension
    assert est.n_evals <= method.budget() + audit_calls(method, rp.base.dim)
    assert est.details["directional"]["n_calls"] == audit_calls(method, 2) > 0
    assert method.progress(est.history[0]).endswith("independent draws")
    assert "accepted" in method.progress(est.history[1])
    record = method.checkpoint(steps[-1], est.history)
    assert json.loads(json.dumps(record))["levels_done"] == len(est.history)
    (table,) = SubsetSimulation.diagnostics(json.loads(json.dumps(est.to_dict())))
    assert table.lines == ("level",) and table.bars == "survivors"
    assert table.column("level") == est.details["levels"]
    assert table.column("acceptance")[0] is None
    assert table.column("moves")[0] == 0 and set(table.column("moves")[1:]) == {2}
    assert SubsetSimulation.diagnostics({"history": []}) == []


def test_subset_simulation_answers_the_mean_of_two_independent_replicates():
    problem = gaussian_linear_problem(2, p=1e-6)
    est = subset_simulation(problem.f, problem.base, problem.gamma, seed=0)
    replicates = est.details["replicates"]
    assert len(replicates) == 2 and est.details["replicate_particles"] == [1000, 1000]
    assert est.p == pytest.approx(np.mean([r["p"] for r in replicates]), rel=1e-12)
    assert abs(est.p - problem.p_exact) < 3 * est.stderr
    assert {h.replicate for h in est.history} == {0, 1}
    method = get_estimator("splitting")
    assert method.progress(est.history[-1]).startswith("replicate 2/2, set ")
    # each replicate may run 1 + 2 + 4 times its levels' bound: 7 in all
    levels = 2000 * 8 + 2000 * 11
    assert method.budget() == 7 * levels and "regrown up to 2x" in method.describe()


def test_subset_simulation_on_a_near_miss_says_caution():
    problem = decoy_problem(0.03)  # a near miss beside the event, never reaching it

    def trust(seed):
        est = subset_simulation(
            problem.f, problem.base, 0.0, seed=seed, n_particles=1000
        )
        as_dict = est.to_dict()
        main = as_dict["by_gamma"][0]
        return est, estimate_trust(estimator_class("splitting"), as_dict, main)

    est, label = trust(2)  # the hits descend from one or two particles of a set
    assert min(est.details["ancestors"]) < 2.0 and est.p > 2 * problem.p_exact
    # Student's t at about one degree of freedom: an interval that holds p
    # and, decades wide, says itself how little one family tells
    assert "Student's t at 1.1 degrees of freedom" in est.main.interval
    low, high = est.ci
    assert low < problem.p_exact < high and high / low > 1e4
    assert "effective particles" not in str(label)
    est, label = trust(6)  # regrown three times: the luckier of several tries
    assert est.details["replicates_regrown"] == 3
    assert "ran out before larger ones reached gamma" in str(label)


def test_chains_correlated_beyond_the_limit_make_the_next_level_move_more():
    independent = ParticleSet(np.arange(100.0).reshape(100, 1), 9.5)
    assert chain_correlation(independent.values, independent.level) == 1.0
    assert moves_after(independent, 2, 3) == 2
    stuck = ParticleSet(np.repeat(np.arange(10.0), 10).reshape(10, 10), 0.5)
    assert chain_correlation(stuck.values, stuck.level) == pytest.approx(10.0)
    assert CORRELATED < 10.0
    assert moves_after(stuck, 2, 3) == 6
    assert moves_after(stuck, 2, 1) == 2


def test_more_moves_only_where_the_cap_on_calls_leaves_room_for_them():
    assert not SplittingSettings().moves_adapt()  # subset simulation's own default
    free = SplittingSettings(n_particles=1000, correlated_moves=2)
    assert free.moves_adapt()
    assert free.bound(0, correlated=True) > free.bound(0)
    assert SubsetSimulation(free).budget() == free.bound(free.regrow, correlated=True)
    full = SplittingSettings(
        n_particles=1000, correlated_moves=2, max_calls=free.bound(0)
    )
    assert not full.moves_adapt()
    assert full.one_replicate(500).correlated_moves == 1
    assert "correlated_moves" not in SplittingSettings().recorded()  # as before it


def test_slowly_mixing_chains_move_more_and_p_is_found_the_same():
    problem = gaussian_linear_problem(2, p=1e-5)
    runs = {
        k: subset_simulation(
            problem.f,
            problem.base,
            problem.gamma,
            n_particles=1000,
            correlated_moves=k,
            seed=3,
        )
        for k in (1, 3)
    }
    moves = {k: {h["moves"] for h in e.to_dict()["history"]} for k, e in runs.items()}
    assert moves[1] == {0, 1}
    assert 3 in moves[3]  # one move per state leaves the chains correlated
    assert runs[3].n_evals > runs[1].n_evals
    for e in runs.values():
        assert abs(e.p - problem.p_exact) < 4 * e.stderr


def test_a_refresh_forgets_the_ancestors_and_keeps_the_conditional_law():
    # f depends on z0 alone (a half-space); particles of f <= 0 that two
    # ancestors left with offsets in coordinates 1-5: drawing those afresh is
    # always accepted and leaves them N(0, 1), z0 untouched; drawing z0 afresh
    # too keeps only proposals below the level
    d, n, c = 6, 4000, 2.0
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))

    def f(x):
        return c - x[:, 0]

    problem = RareEventProblem(base, f, 0.0)
    rng = np.random.default_rng(0)
    ancestors = np.repeat(rng.normal(0.0, 1.0, (2, d)), n // 2, axis=0)
    z = rng.standard_normal((n, d)) * 0.5 + ancestors
    z[:, 0] = stats.truncnorm.rvs(c, np.inf, size=n, random_state=rng)
    values = f(z).reshape(400, 10)
    moved = MovedSet(z, values, 0.3, 0, 0.5, 7, 0, 0)
    others = np.arange(d) > 0
    out, accepted = refreshed(moved, 0.0, others, problem, EstimationContext(seed=1))
    assert accepted == 1.0 and out.n_calls == n and out.n_stages == 8
    assert np.array_equal(out.z[:, 0], z[:, 0])
    assert np.abs(out.z[:, 1:].mean(axis=0)).max() < 4 / np.sqrt(n)
    assert out.z[:, 1:].var(axis=0) == pytest.approx(np.ones(d - 1), abs=0.1)
    every = np.ones(d, dtype=bool)
    out, accepted = refreshed(moved, 0.0, every, problem, EstimationContext(seed=1))
    assert accepted == pytest.approx(stats.norm.sf(c), abs=0.01)  # P0(f <= 0)
    assert np.all(f(out.z) <= 0.0) and np.array_equal(out.values.ravel(), f(out.z))
