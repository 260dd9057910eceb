"""Importance sampling from splitting's particles: exact problems, fit, seeds."""

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare import (
    FixedCovNormal,
    Product,
    ScaledBeta,
    get_estimator,
    splitting_is,
    subset_simulation,
)
from avrisk.rare.cross_entropy import CESettings
from avrisk.rare.cross_entropy_search import SEARCH_ADVICE
from avrisk.rare.estimator import estimator_class
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.families.standard_space_normal import VARIANCE_RANGE
from avrisk.rare.particle_fit import particle_proposal
from avrisk.rare.particle_predictions import (
    PREDICTION_FOLDS,
    HeldOutWeights,
    held_out_weights,
)
from avrisk.rare.particle_shifts import slope_direction
from avrisk.rare.results import GammaEstimate
from avrisk.rare.splitting import SubsetSimulation
from avrisk.rare.splitting_importance import (
    SplittingImportanceSampling,
    SplittingISSettings,
)
from avrisk.rare.splitting_is_answer import ADVICE, levels_more_precise
from avrisk.rare.splitting_is_tables import shift_kind
from avrisk.rare.trust import estimate_trust
from avrisk.report.plots import table_cells
from avrisk.testing import (
    beta_sum_problem,
    check_estimator,
    four_branch_problem,
    gaussian_linear_problem,
)
from avrisk.testing.generated import decoy_problem
from avrisk.testing.suite import suite_problem
from tests.interrupts import ctrl_c_when, without_wall_time


def sis(problem, seed=0, **kw):
    kw = {"n_particles": 2000, "n_final": 5000, **kw}
    return splitting_is(problem.f, problem.base, problem.gamma, seed=seed, **kw)


@pytest.mark.parametrize(
    "problem",
    [
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(20, p=1e-6),
        beta_sum_problem(6, p=1e-5),
        four_branch_problem(),
    ],
    ids=lambda p: p.name,
)
def test_finds_p_of_exact_problems_within_its_stderr(problem):
    est = check_estimator(sis, problem, seed=4)
    assert est.n_samples == 5000  # the estimate is the importance-sampling stage's
    # each replicate's last set (level gamma) seeds moves at gamma: N / 2 states,
    # each made by the default's n_moves proposals
    lasts = [h for h in est.history if h.level == problem.gamma]
    assert [h.replicate for h in lasts] == [0, 1]
    per_state = SplittingISSettings().gamma_moves()
    moves = per_state * sum(1000 - h.n_survivors for h in lasts)
    rays = est.details.get("directional", {}).get("n_calls", 0)  # X in d <= 8
    assert est.n_evals == est.history[-1].n_evals + moves + 5000 + rays
    assert not est.details["replicates_disagree"]
    assert est.main.pareto_k < 0.7
    levels = est.details["splitting"][str(problem.gamma)]
    assert levels["ci"][0] <= levels["p"] <= levels["ci"][1]  # the cross-check


def test_more_moves_at_gamma_cost_their_calls_and_leave_the_levels_alone():
    problem = gaussian_linear_problem(10, p=1e-6)
    fixed = {"seed": 2, "correlated_moves": 1}  # moves at gamma as set, no more
    one, three = sis(problem, **fixed), sis(problem, **fixed, moves_at_gamma=3)
    assert one.history == three.history  # the same levels, draw for draw
    lasts = [h for h in one.history if h.level == problem.gamma]
    moved = sum(1000 - h.n_survivors for h in lasts)  # states moved at gamma
    default = SplittingISSettings().n_moves
    assert three.n_evals - one.n_evals == (3 - default) * moved
    assert abs(three.p - problem.p_exact) < 4 * three.stderr
    settings = estimator_class("splitting_is").Settings
    assert "moves_at_gamma" not in settings().recorded()  # older records hold
    assert settings(moves_at_gamma=3).recorded()["moves_at_gamma"] == 3


def test_the_four_branches_get_a_component_each():
    est = sis(four_branch_problem(), seed=1, n_particles=4000)
    assert est.details["n_components"] == 4
    means = np.array([c.mean for c in est.proposal.components])
    # one shift per quadrant direction (+-1, +-1) / sqrt 2, each at the branch
    directions = {tuple(np.sign(m).astype(int)) for m in means}
    assert directions == {(1, 1), (-1, -1), (1, -1), (-1, 1)}


def test_one_region_in_high_dimension_is_one_component():
    # k-means cuts 600 particles in 200 dimensions into clusters by noise alone;
    # the held-out half of the chains says one component fits them better
    d, rng = 200, np.random.default_rng(0)
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    z = rng.standard_normal((600, d))
    z[:, 0] += 4.0
    chain = np.repeat(np.arange(60), 10)
    q = particle_proposal(z, chain, base, SplittingISSettings(), rng).proposal
    assert q.n_components == 1
    assert q.components[0].mean[0] == pytest.approx(4.0, abs=0.2)


def test_where_the_event_narrows_p0_the_proposal_fits_the_variances():
    # RP63: x1 >= 0.1 sum(x2..x100 ^ 2) - 4.5 holds the 99 squares small, so
    # P0(. | F) is narrower than P0 in 99 coordinates; unit-variance shifts pay
    # for it in each of them
    problem = suite_problem("RP63")
    runs = {
        fit: sis(problem, n_particles=4000, n_final=20_000, fit_variances=fit)
        for fit in (True, False)
    }
    assert runs[True].details["fitted_variances"]
    assert not runs[False].details["fitted_variances"]
    # shifts alone are answered by the levels, the fitted variances by the
    # importance sample, worth more than ten times as many draws
    assert runs[True].stderr < runs[False].stderr / np.sqrt(10)
    assert abs(runs[True].p - problem.p_exact) < 4 * runs[True].stderr
    table = runs[True].proposal.to_dict()["components"][0]
    assert table["family"] == "StandardSpaceNormal"
    assert np.median(table["variance"][1:]) < 0.9  # narrower, not at the floor
    assert min(table["variance"]) >= VARIANCE_RANGE[0]


def _mean_shift_fitter(base, scale=1.0):
    """A fitter of one shift, the mean of the points it is given (times scale)."""

    def fitter(points, point_chain):
        shift = StandardSpaceShift(base, scale * points.mean(axis=0))
        return [shift], np.ones(1), np.ones(base.dim, dtype=bool)

    return fitter


def test_held_out_weights_are_the_particles_p0_over_q():
    # particles N(m, 0.3^2) around m = (3, 0); a shift to their mean m has
    # q / p0 = exp(m.z - |m|^2 / 2), so each weighs 1 / (lam + (1 - lam) q /
    # p0) < 1, and the mean of that under fits to the other folds is about
    # its value at the true m
    d, lam = 2, 0.1
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    rng = np.random.default_rng(3)
    m = np.array([3.0, 0.0])
    z = rng.normal(m, 0.3, (2000, d))
    chain = np.repeat(np.arange(200), 10)
    held_out = held_out_weights(z, chain, _mean_shift_fitter(base), base, lam, rng)
    expected = np.mean(1.0 / (lam + (1 - lam) * np.exp(z @ m - m @ m / 2)))
    assert held_out.uncovered == 0.0
    assert held_out.covered_mean_weight == pytest.approx(expected, rel=0.05)
    # a fit that stays at P0 (its shift zero) covers none of them: w = 1
    at_p0 = held_out_weights(z, chain, _mean_shift_fitter(base, 0.0), base, lam, rng)
    assert at_p0 == (1.0, 0.0)
    # fewer chains than folds: nothing to hold out
    few = np.arange(len(z)) % (PREDICTION_FOLDS - 1)
    assert np.isnan(
        held_out_weights(z, few, _mean_shift_fitter(base), base, lam, rng).uncovered
    )


def test_the_levels_answer_when_the_particles_predict_them_more_precise():
    levels = GammaEstimate(0.0, 1e-6, 2e-7, (6e-7, 1.4e-6), 50, 50.0, 4000)
    # the sample's relative variance per draw 1e-4 / 1e-6 - 1 = 99; over
    # 10,000 draws 0.0099 < 0.04 = (0.2)^2: importance sampling; with 10
    # times the weight 0.0999 > 0.04: the levels
    assert not levels_more_precise(HeldOutWeights(0.0, 1e-4), levels, 10_000)
    assert levels_more_precise(HeldOutWeights(0.0, 1e-3), levels, 10_000)
    # a share of p the sample will miss counts as its error squared: 10%
    # (0.01) no, 25% (0.0625) more than the levels' 0.04
    assert not levels_more_precise(HeldOutWeights(0.1, 1e-5), levels, 10_000)
    assert levels_more_precise(HeldOutWeights(0.25, 1e-5), levels, 10_000)
    nan = float("nan")
    assert not levels_more_precise(HeldOutWeights(nan, nan), levels, 10_000)


def test_five_regions_in_fifty_dimensions_are_answered_by_the_levels():
    # five half-space regions of unequal mass in d = 50: a few mean shifts
    # cannot hold them all (the importance sample came out 18% low, 8 of 20
    # covered); the particles predict it, and the levels' product answers.
    # Shifts alone: fitted variances hold this seed's regions well enough
    # that its sample answers, which is not the choice tested here
    problem = suite_problem("kregions_k5_d50_p1e-06")
    est = sis(problem, seed=0, n_particles=4000, n_final=20_000, fit_variances=False)
    assert est.details["answer"] == "splitting"
    levels = est.details["splitting"][str(problem.gamma)]
    assert est.p == levels["p"] and list(est.ci) == levels["ci"]
    assert est.ci[0] <= problem.p_exact <= est.ci[1]
    sampled = est.details["importance_sampling"][str(problem.gamma)]
    assert sampled["p"] != est.p  # the sample is kept beside it


def test_a_weak_shift_of_every_coordinate_is_kept_and_noise_is_dropped():
    # dense: 0.3 sd on each of 100 coordinates (2-3 standard errors each); sparse:
    # 4 sd on one of 100, noise on the others; the held-out half picks the threshold
    d, rng = 100, np.random.default_rng(1)
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    chain = np.repeat(np.arange(100), 8)
    dense = particle_proposal(
        rng.standard_normal((800, d)) + 0.3, chain, base, SplittingISSettings(), rng
    )
    assert dense.n_shifted >= 90 and dense.threshold <= 2.0
    sparse_z = rng.standard_normal((800, d))
    sparse_z[:, 0] += 4.0
    sparse = particle_proposal(sparse_z, chain, base, SplittingISSettings(), rng)
    assert sparse.n_shifted <= 5 and sparse.threshold >= 3.0


def test_a_shift_spread_over_many_coordinates_is_shrunk_towards_the_truth():
    # 0.15 sd on each of 1000 coordinates (|a|^2 = 22.5), 400 particles: no one
    # coordinate stands out, so every coordinate is kept (t = 0), and the fitted
    # mean's noise (about 1000 / 400 in squared norm) is shrunk out of it
    d, rng = 1000, np.random.default_rng(2)
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    z = rng.standard_normal((400, d)) + 0.15
    fit = particle_proposal(
        z, np.arange(400) // 4, base, SplittingISSettings(n_components=1), rng
    )
    assert fit.threshold == 0.0 and fit.n_shifted == d
    (component,) = fit.proposal.components
    raw_error = np.sum((z.mean(axis=0) - 0.15) ** 2)
    shrunk_error = np.sum((component.mean - 0.15) ** 2)
    assert raw_error == pytest.approx(d / 400, rel=0.15)
    assert shrunk_error < 0.9 * raw_error
    scale = component.mean @ z.mean(axis=0) / np.sum(z.mean(axis=0) ** 2)
    assert scale == pytest.approx(22.5 / (22.5 + d / 400), abs=0.03)


def test_f_falls_along_the_least_squares_slope():
    rng = np.random.default_rng(3)
    z = rng.standard_normal((300, 20))
    u = rng.standard_normal(20)
    u /= np.linalg.norm(u)
    assert slope_direction(z, 3.0 - z @ u) == pytest.approx(u, abs=1e-9)
    values = 3.0 - z @ u
    values[::2] = np.inf  # failed evaluations are left out
    assert slope_direction(z, values) == pytest.approx(u, abs=1e-9)
    assert slope_direction(z[:21], 3.0 - z[:21] @ u) is None  # fewer than D + 2
    assert slope_direction(z, np.ones(300)) is None  # flat


def test_a_shift_spread_over_many_coordinates_is_found_along_the_slope():
    # 0.15 sd on each of 1000 coordinates, 400 particles (as above), and f's
    # slope known: the held-out half prefers one shift along it, whose noise is
    # 1 / 400 against the per-coordinate fit's 1000 / 400
    d, rng = 1000, np.random.default_rng(2)
    base = FixedCovNormal(np.zeros(d), cov=np.eye(d))
    z = rng.standard_normal((400, d)) + 0.15
    chain = np.arange(400) // 4
    settings = SplittingISSettings(n_components=1)
    slope = np.ones(d) / np.sqrt(d)
    fit = particle_proposal(z, chain, base, settings, rng, slope)
    assert fit.along_slope and fit.n_shifted == d
    (component,) = fit.proposal.components
    coordinates = particle_proposal(z, chain, base, settings, rng)
    assert not coordinates.along_slope
    error = np.sum((component.mean - 0.15) ** 2)
    assert error < 0.1 * np.sum((coordinates.proposal.components[0].mean - 0.15) ** 2)
    assert error < 0.05


def test_a_slope_that_misses_the_failure_regions_is_not_chosen():
    # two regions at +-4 along coordinate 0; a slope along coordinate 1 says
    # nothing of them (a nonlinear f's average slope can point anywhere)
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    rng = np.random.default_rng(0)
    z = np.vstack(
        [rng.normal((4, 0), 0.3, (500, 2)), rng.normal((-4, 0), 0.3, (500, 2))]
    )
    chain = rng.permutation(1000) // 10
    fit = particle_proposal(
        z, chain, base, SplittingISSettings(), rng, np.array([0.0, 1.0])
    )
    assert not fit.along_slope and fit.proposal.n_components == 2


def test_shift_searched_leaves_unsearched_coordinates_at_zero():
    base = Product(
        [
            ScaledBeta(2.0, 2.0, lo=0.0, scale=1.0, bounds=(1.0, 3.9)),
            FixedCovNormal(np.zeros(2), cov=np.eye(2), max_shift=0.0),
        ]
    )
    rng = np.random.default_rng(0)
    z = rng.standard_normal((400, 3)) + 3.0
    chain = np.arange(400) // 4
    for shift, moved in (("all", [True, True, True]), ("searched", [True, 0, 0])):
        settings = SplittingISSettings(shift=shift, n_components=1)
        fit = particle_proposal(z, chain, base, settings, rng)
        (component,) = fit.proposal.components
        np.testing.assert_array_equal(component.mean != 0, moved)


@pytest.mark.slow
def test_the_95_percent_interval_covers_p_in_most_runs():
    problems = [gaussian_linear_problem(20, p=1e-6), four_branch_problem()]
    covered = {
        problem.name: np.mean(
            [
                lo <= problem.p_exact <= hi
                for lo, hi in (sis(problem, seed=100 + s).ci for s in range(80))
            ]
        )
        for problem in problems
    }
    # four-branch at this small budget covers about 87% (100 seeds, one or two
    # moves per state alike; 40 seeds left it to the luck of the draw)
    assert np.mean(list(covered.values())) >= 0.88, covered
    assert min(covered.values()) >= 0.85, covered


def test_same_seed_same_result_whatever_the_batch_size():
    problem = four_branch_problem()
    whole = sis(problem, seed=3, n_particles=500, n_final=2000)
    batched = sis(problem, seed=3, n_particles=500, n_final=2000, batch_size=37)
    assert whole.to_dict() | {"wall_time_s": 0} == batched.to_dict() | {
        "wall_time_s": 0
    }


def test_an_interrupted_run_resumes_to_the_same_summary(tmp_path):
    problem = gaussian_linear_problem(2, p=1e-4)
    settings = RunSettings(
        "splitting_is", gamma=0.0, seed=2, n_particles=500, n_final=3000
    )

    def run(path, f=problem.f):
        directory = RunDirectory(path, ["x0", "x1"])
        return run_estimation(directory, problem.base, f, settings)

    reference = run(tmp_path / "reference")
    # in the moves at gamma or the final stage
    interrupted, _ = ctrl_c_when(problem.f, lambda sizes: len(sizes) == 30)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "run", f=interrupted)
    resumed = run(tmp_path / "run")
    assert resumed["method"] == "splitting_is"
    assert without_wall_time(resumed["estimate"]) == without_wall_time(
        reference["estimate"]
    )


def test_settings_budget_and_description():
    plan = dict(n_particles=400, max_levels=6, n_final=900)
    method = get_estimator("splitting_is", **plan, regrow=0)
    # 8 N draws on a plateau, 2 proposals per state at 5 further levels and at
    # gamma, 2 refresh rounds there, then the final draws; twice the moves
    # after correlated chains
    assert method.planned_budget() == 400 * (8 + 5 * 2) + 400 * (2 + 2) + 900
    assert method.budget() == 400 * (8 + 5 * 2 * 2) + 400 * (2 * 2 + 2) + 900
    assert method.describe() == (
        "subset simulation, 400 particles per level, p0 0.1, 2 moves per state, "
        "2 refresh rounds, then IS 900 (4 components, defensive 0.1)"
    )
    assert (
        "refresh"
        not in get_estimator(
            "splitting_is", **plan, regrow=0, refresh_rounds=0
        ).describe()
    )
    # each replicate regrown twice: 1 + 2 + 4 times the levels, 4 times at gamma
    regrown = get_estimator("splitting_is", **plan)
    assert regrown.budget() == 7 * 400 * (8 + 5 * 2 * 2) + 4 * 400 * (2 * 2 + 2) + 900
    assert "regrown up to 2x" in regrown.describe()
    capped = get_estimator("splitting_is", **plan, max_calls=10_000)
    assert capped.budget() == 10_000
    with pytest.raises(ValueError, match="less than the run's bound without regrowth"):
        get_estimator("splitting_is", **plan, max_calls=6_000)
    with pytest.raises(ValueError, match="shift"):
        get_estimator("splitting_is", shift="some")
    est = sis(gaussian_linear_problem(2, p=1e-4), seed=0, n_particles=300)
    assert json.loads(json.dumps(est.to_dict()))["method"] == "splitting_is"


def test_diagnostics_show_the_levels_the_proposal_and_the_cross_check():
    problem = gaussian_linear_problem(2, p=1e-4)
    est = splitting_is(
        problem.f, problem.base, problem.gamma, seed=1, gamma_test=(0.5,),
        n_particles=400, n_final=2000,
    )  # fmt: skip
    summary = json.loads(json.dumps(est.to_dict()))  # as read from summary.json
    *levels, fit, check = SplittingImportanceSampling.diagnostics(summary)
    assert levels == SubsetSimulation.diagnostics(summary)
    # one plot per replicate, each numbering its sets from 0
    assert [t.title for t in levels] == [
        f"Subset simulation levels, replicate {r}" for r in (1, 2)
    ]
    assert all(t.drawn and t.column("set")[0] == 0 for t in levels)
    assert sum(len(t.rows) for t in levels) == len(est.history)
    assert not fit.drawn and not check.drawn  # shown as tables
    (row,) = fit.rows
    shown = dict(zip(fit.columns, row, strict=True))
    details = est.details
    assert shown["components"] == details["n_components"] >= 1
    assert shown["shifted coordinates"] == details["n_shifted"] <= 2
    assert shown["threshold [SE]"] == details["informative_threshold"]
    assert shown["shift"] == shift_kind(details)
    assert shift_kind({"along_slope": False, "fitted_variances": True}) == "coords+var"
    assert shift_kind({"along_slope": True}) == "slope"
    assert shown["acceptance at gamma"] == details["fit_acceptance"]
    assert shown["hits"] == est.n_hits > 0
    assert shown["ESS"] == pytest.approx(est.ess)
    assert shown["Pareto k"] == pytest.approx(est.main.pareto_k)
    assert check.column("gamma") == [0.0, 0.5]  # every threshold, in order
    for g, p, ci, own, own_ci in check.rows:
        assert (p, ci) == (est.by_gamma[g].p, list(est.by_gamma[g].ci))
        assert own == details["splitting"][str(g)]["p"] != p
        assert own_ci == details["splitting"][str(g)]["ci"]
    assert table_cells(check)[0][2] == "..".join(f"{c:.3g}" for c in est.ci)
    # a summary without the importance-sampling details: the levels alone
    without = {k: v for k, v in summary.items() if k != "details"}
    assert SplittingImportanceSampling.diagnostics(without) == levels


def test_each_estimators_advice_names_only_its_own_settings():
    named = {  # setting names: snake_case words, and the single-word ones
        advice: set(re.findall(r"\b[a-z]+_[a-z_]+\b|\brho\b|\bdefensive\b", text))
        for advice in (ADVICE, SEARCH_ADVICE)
        for text in [" ".join(advice)]
    }
    assert named[ADVICE] == {"n_final", "n_particles", "defensive"}
    assert named[ADVICE] <= set(SplittingISSettings.model_fields)
    assert named[SEARCH_ADVICE] == {"n_final", "n_iter", "n_per_iter", "rho"}
    assert named[SEARCH_ADVICE] <= set(CESettings.model_fields)


def test_a_plateau_nothing_leaves_gives_the_levels_bound():
    # f = 7 everywhere but where x_0 > 6 (P0 1e-9): no draw leaves the tie
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    est = splitting_is(
        lambda x: np.where(x[:, 0] > 6.0, -1.0, 7.0), base, 0.0, n_particles=500
    )
    assert est.method == "splitting_is" and est.details["bound_only"]
    # two replicates of 250 particles, each of 2,000 draws, 1,750 counted; then
    # the rays (X in two dimensions), which reach x_0 > 6 but not above the bound
    rays = est.details["directional"]
    assert est.p == 0.0 and est.n_evals == 4000 + rays["n_calls"]
    assert rays["rays_in_event"] > 0 and not rays["doubt"]
    assert est.ci == (0.0, pytest.approx(-np.expm1(np.log(0.025) / 1750)))


def test_every_stage_of_the_replicates_and_their_moves_is_its_own():
    # a stage's random numbers and its record are keyed by its number: the
    # moves at gamma of the first replicate must not reuse the second's
    seen = []
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    splitting_is(
        lambda x: 3.0 - x[:, 0],
        base,
        0.0,
        n_particles=200,
        n_final=200,
        on_batch=lambda batch: seen.append((batch.stage, batch.chunk)),
    )
    assert len(seen) == len(set(seen))


def test_a_replicate_whose_levels_run_out_is_left_out_with_a_caution():
    # p = 1e-6 takes about 7 sets at p0 = 0.1: with 6, one replicate of seed 0
    # runs out above gamma, the other reaches it and the proposal is its own
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    b = stats.norm.isf(1e-6)
    f = lambda x: b - x.sum(axis=1) / np.sqrt(2)  # noqa: E731
    plan = dict(n_particles=400, n_final=2000, regrow=0, n_moves=1)
    est = splitting_is(f, base, 0.0, **plan, max_levels=6)
    assert est.details["replicates_exhausted"] == 1
    assert len(est.details["replicates"]) == 1
    assert abs(est.p - 1e-6) < 4 * est.stderr  # one seed: not a 95% check
    trust = estimate_trust(
        estimator_class("splitting_is"), est.to_dict(), est.to_dict()["by_gamma"][0]
    )
    assert "1 of the 2 replicates of the search did not reach gamma" in str(trust)
    # with one level fewer neither does: importance sampling from the deepest
    # sets, with caution (subset simulation alone: its first draws' bound)
    deepest = splitting_is(f, base, 0.0, **plan, max_levels=5)
    assert deepest.details["replicates_exhausted"] == 2
    assert "no replicate of the search reached gamma" in str(trust_of(deepest))
    alone = subset_simulation(f, base, 0.0, n_particles=400, max_levels=5)
    assert alone.p == 0.0 and alone.details["bound_only"] and alone.ci[1] > 1e-6
    assert "naive sampling's of their first draws" in str(trust_of(alone, "splitting"))


def _decoy_run(seed, **options):
    """splitting_is on a near-miss mechanism that never ends in the event.

    One move per state, never more (``correlated_moves=1``), so that the seeds
    below follow the decoy as described.
    """
    problem = decoy_problem(0.03)
    est = splitting_is(
        problem.f, problem.base, problem.gamma, seed=seed, n_particles=400,
        n_final=5000, n_moves=1, correlated_moves=1, **options,
    )  # fmt: skip
    return problem, est, trust_of(est)


def trust_of(est, method="splitting_is"):
    as_dict = est.to_dict()
    main = next(g for g in as_dict["by_gamma"] if g["gamma"] == est.gamma)
    return estimate_trust(estimator_class(method), as_dict, main)


def test_a_replicate_that_runs_out_of_levels_runs_again_twice_as_large():
    problem, est, trust = _decoy_run(1)
    # the first replicate followed the decoy twice (200, then 400 particles)
    assert est.details["replicates_regrown"] == 2
    assert est.details["replicates_exhausted"] == 0
    assert est.details["replicate_particles"] == [200, 800]
    assert abs(est.p - problem.p_exact) < 3 * est.stderr
    assert "did not reach gamma" not in str(trust)  # both replicates did
    planned = get_estimator(
        "splitting_is", n_particles=400, n_final=5000, n_moves=1, correlated_moves=1
    )
    assert est.n_evals <= planned.budget()
    # without regrowth the same seed rests on one replicate; the decoy it
    # followed holds about 1e-12 at its deepest level, far below the
    # importance sample's error, so that alone is no doubt (the run's
    # weights and levels say caution for their own reasons)
    _, plain, plain_trust = _decoy_run(1, regrow=0)
    assert plain.details["replicates_exhausted"] == 1
    (mass,) = plain.details["exhausted_mass"]
    assert mass["upper"] < 1e-3 * plain.stderr and mass["level"] > problem.gamma
    assert "did not reach gamma" not in str(plain_trust) and not plain_trust.ok
    # a cap that holds only the plan leaves no room to regrow
    cap = get_estimator(
        "splitting_is",
        n_particles=400,
        n_final=5000,
        n_moves=1,
        correlated_moves=1,
        regrow=0,
    )
    _, capped, _ = _decoy_run(1, max_calls=cap.budget())
    assert capped.details["replicates_regrown"] == 0
    assert capped.n_evals <= cap.budget()


def test_no_replicate_reaching_gamma_is_an_estimate_with_caution_not_an_error():
    _, est, trust = _decoy_run(4)
    assert est.details["replicates_exhausted"] == 2 and est.p == 0.0
    assert est.details["splitting"] == {}  # the decoy's product is no estimate
    assert not trust.ok and "no replicate of the search reached gamma" in str(trust)


def test_refreshes_at_gamma_cost_their_calls_and_leave_the_levels_alone():
    # a half-space along z0 in 10 coordinates: the refresh draws the other
    # nine afresh, always accepted
    base = FixedCovNormal(np.zeros(10), cov=np.eye(10))
    beta = stats.norm.isf(1e-6)

    def f(x):
        return beta - x[:, 0]

    half_space = SimpleNamespace(base=base, f=f, gamma=0.0, p_exact=1e-6)
    fixed = {"seed": 2, "correlated_moves": 1}
    plain = sis(half_space, **fixed, refresh_rounds=0)
    fresh = sis(half_space, **fixed)  # two rounds, the default
    assert plain.history == fresh.history  # the same levels, draw for draw
    assert "refreshed" not in plain.details
    assert fresh.details["refreshed"] == [{"coordinates": 9, "acceptance": 1.0}] * 2
    assert fresh.n_evals - plain.n_evals == 2 * 2000  # one call per particle
    assert abs(fresh.p - 1e-6) < 4 * fresh.stderr
    # along every coordinate alike, every coordinate looks uninformed once the
    # errors are widened: no refresh is made
    linear = gaussian_linear_problem(10, p=1e-6)
    assert sis(linear, **fixed, refresh_rounds=2).details["refreshed"] == []
    settings = estimator_class("splitting_is").Settings
    # runs recorded before the default changed (0 then, unrecorded) resume
    # with 0 given; the default's runs say so, so the two never mix
    assert "refresh_rounds" not in settings(refresh_rounds=0).recorded()
    assert settings().recorded()["refresh_rounds"] == 2
    plan = dict(n_particles=400, max_levels=6, n_final=900, regrow=0)
    more = settings(**plan).bound(0) - settings(**plan, refresh_rounds=0).bound(0)
    assert more == 2 * 400
