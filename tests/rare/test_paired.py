"""The paired comparison of two versions (avrisk.rare.paired) on exact pairs."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from avrisk.rare.paired import PAIRED_DEFAULTS, MinOfPair, paired_splitting_is
from avrisk.rare.paired_gate import gate
from avrisk.rare.paired_intervals import discordance_bound, fieller_interval
from avrisk.rare.problem import InvalidOutputError
from avrisk.rare.splitting_importance import splitting_is
from avrisk.testing.pairs import AnalyticPair, pair_problem

#: The settings of these tests: small runs, fixed seeds.
SMALL = {"n_particles": 1000, "n_final": 4000}


def run(pair: AnalyticPair, seed: int = 0, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return paired_splitting_is(
            pair.f, pair.base, pair.gamma, seed=seed, **{**SMALL, **kw}
        )


def within(value: float, truth: float, stderr: float, k: float = 4.0) -> bool:
    return abs(value - truth) <= k * stderr


@pytest.mark.parametrize(
    "name",
    [
        "nested_r0.3_p1e-04_d4",
        "overlap_r0.2_p1e-04_d4",
        "disjoint_ratio2_p1e-04_d4",
    ],
)
def test_every_figure_is_within_its_own_errors_of_the_exact_one(name):
    pair = pair_problem(name)
    est = run(pair, seed=1)
    assert within(est.a.p, pair.p_a, est.a.stderr)
    assert within(est.b.p, pair.p_b, est.b.stderr)
    assert within(est.difference.value, pair.difference, est.difference.stderr)
    assert within(est.ratio.value, pair.ratio, est.ratio.stderr)
    for part in (est.a, est.b, est.difference, est.ratio):
        lo, hi = part.ci
        assert lo < hi
    assert est.ratio.ci[0] <= est.ratio.lower <= est.ratio.value
    assert est.ratio.value <= est.ratio.upper <= est.ratio.ci[1]
    # regressions less fixes is the plain paired difference; the controlled
    # one (the proposal's components as control variates) is within its own
    # standard error of it
    assert "control variates" in est.difference.interval
    plain = est.regressions.p - est.fixes.p
    assert abs(est.difference.value - plain) < est.difference.stderr
    assert est.trust.ok, est.trust


def test_a_nested_fix_has_fixes_and_no_regression():
    pair = pair_problem("nested_r0.3_p1e-04_d4")  # B's failures inside A's
    est = run(pair)
    assert est.regressions.n_hits == 0 and est.fixes.n_hits > 100
    assert est.regression_share == 0.0
    assert within(est.fix_share, 0.3, 4 * est.fixes.stderr / est.a.p)
    # no regression sampled: its interval is the discordance bound, not 0 wide,
    # and the difference's upper end makes room for it (B may regress unseen)
    bound = est.regressions.ci[1]
    assert est.regressions.ci[0] == 0.0 and bound > 0.0
    d = est.difference
    assert d.ci[0] == pytest.approx(d.value - 1.959964 * d.stderr, rel=1e-6)
    assert d.ci[1] == pytest.approx(d.value + 1.959964 * d.stderr + bound, rel=1e-6)
    assert d.upper == pytest.approx(d.value + 1.644854 * d.stderr + bound, rel=1e-6)


def test_the_paired_difference_has_a_smaller_error_than_two_independent_ones():
    pair = pair_problem("nested_r0.05_p1e-04_d4")
    est = run(pair)
    independent = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for which, seed in ((0, 11), (1, 12)):
            problem = pair.version(which)
            independent.append(
                splitting_is(
                    problem.f,
                    problem.base,
                    0.0,
                    seed=seed,
                    n_particles=500,
                    n_final=2000,
                )
            )
    independent_se = math.hypot(*(e.stderr for e in independent))
    assert est.difference.stderr < independent_se / 3


def test_the_search_runs_at_the_paired_defaults_unless_told_otherwise():
    pair = pair_problem("nested_r0.05_p1e-04_d4")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = paired_splitting_is(pair.f, pair.base, 0.0, seed=3)
        told = paired_splitting_is(pair.f, pair.base, 0.0, seed=3, n_final=3000)
    assert default.a.n_samples == PAIRED_DEFAULTS["n_final"]
    assert told.a.n_samples == 3000
    # the levels are the defaults' in both: their calls are the same
    levels = default.n_evals - PAIRED_DEFAULTS["n_final"]
    assert told.n_evals - 3000 == levels
    # half the particles of a single-version run: about half its levels' calls
    single = splitting_is(pair.version(0).f, pair.base, 0.0, seed=3, n_final=1)
    assert 0.3 < levels / (single.n_evals - 1) < 0.7


def test_identical_versions_get_an_honest_nonzero_interval():
    pair = pair_problem("nested_r0_p1e-04_d4")  # the same failure set twice
    est = run(pair)
    assert est.regressions.n_hits == est.fixes.n_hits == 0
    lo, hi = est.difference.ci
    assert lo < 0.0 < hi
    # at most the union's bound times the zero-hit bound of a share
    # among the union's effective hits (about 4 / 4000 here)
    assert hi <= est.a.ci[1] * 5.0 / est.a.ess
    assert est.ratio.ci[0] < 1.0 < est.ratio.ci[1]
    assert est.ratio.lower < 1.0 < est.ratio.upper
    assert not est.trust.ok
    assert any("exactly one of A and B" in r for r in est.trust.reasons)


def test_the_discordance_bound_is_the_zero_hit_bound_of_a_share():
    log_w = np.log(np.full(100, 2.0))
    union = np.zeros(100, bool)
    union[:50] = True  # 50 equally weighted hits
    bound = discordance_bound(log_w, union, 1e-3)
    assert bound == pytest.approx(1e-3 * (1 - 0.025 ** (1 / 50)))
    assert discordance_bound(log_w, np.zeros(100, bool), 1e-3) == 1e-3


def test_fieller_agrees_with_the_delta_method_for_precise_means():
    cov = np.array([[1e-6, 5e-7], [5e-7, 2e-6]])
    lo, hi = fieller_interval((1.0, 1.5), cov, 1.96)
    se = math.sqrt(cov[1, 1] - 2 * 1.5 * cov[0, 1] + 1.5**2 * cov[0, 0])
    assert lo == pytest.approx(1.5 - 1.96 * se, rel=1e-3)
    assert hi == pytest.approx(1.5 + 1.96 * se, rel=1e-3)


def test_fieller_is_unbounded_when_the_denominator_may_be_zero():
    cov = np.diag([1.0, 0.01])
    lo, hi = fieller_interval((1.0, 2.0), cov, 1.96)
    assert hi == math.inf and 0.0 < lo < 2.0  # mean_b clearly above 0
    lo, hi = fieller_interval((1.0, 0.1), cov, 1.96)
    assert (lo, hi) == (0.0, math.inf)


def test_fieller_covers_the_ratio_of_normal_means_at_its_level():
    rng = np.random.default_rng(0)
    cov = np.array([[0.04, 0.03], [0.03, 0.09]])
    means = rng.multivariate_normal([1.0, 0.8], cov, size=4000)
    hits = [
        lo <= 0.8 <= hi for lo, hi in (fieller_interval(m, cov, 1.96) for m in means)
    ]
    assert 0.94 <= np.mean(hits) <= 0.96


def test_a_pair_of_the_wrong_shape_is_refused():
    f = MinOfPair(lambda x: x[:, 0])
    with pytest.raises(InvalidOutputError, match=r"shape \(3, 2\)"):
        f(np.zeros((3, 2)))


def test_a_seeded_pair_gets_its_seeds_and_passes_its_outputs_on():
    def pair(x, seeds):
        return {"f": np.stack([seeds * 1.0, -seeds * 1.0], 1), "status": seeds * 0}

    pair.needs_seeds = True
    f = MinOfPair(pair)
    assert f.needs_seeds
    out = f(np.zeros((2, 1)), seeds=np.array([3, 4]))
    assert out["f"].tolist() == [-3.0, -4.0] and out["f_a"].tolist() == [3.0, 4.0]
    assert out["status"].tolist() == [0, 0]


def test_a_resumed_run_replays_the_final_stage_and_gives_the_same_estimate():
    pair = pair_problem("overlap_r0.2_p1e-04_d4")
    record = {}
    first = run(pair, on_batch=lambda b: record.setdefault((b.stage, b.chunk), b))
    calls = []

    def counting(x):
        calls.append(len(x))
        return pair.f(x)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = paired_splitting_is(
            counting,
            pair.base,
            0.0,
            cache=lambda stage, chunk: record.get((stage, chunk)),
            **SMALL,
        )
    assert not calls  # everything replayed
    assert again.to_dict() | {"union": None} == first.to_dict() | {"union": None}
    assert again.union["p"] == first.union["p"]


def test_a_search_that_finds_no_failure_bounds_every_figure():
    def never(x):
        return np.ones((len(x), 2))

    base = pair_problem("nested_r0_p1e-04_d2").base
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = paired_splitting_is(never, base, 0.0, n_particles=200, n_final=500)
    assert est.a.p == est.b.p == 0.0
    assert 0.0 < est.a.ci[1] == est.difference.ci[1] == -est.difference.ci[0]
    assert est.ratio.ci == (0.0, math.inf)
    assert not est.trust.ok


def test_the_gate_passes_half_the_risk_fails_twice_and_cannot_tell_equal():
    half = run(pair_problem("nested_r0.5_p1e-04_d4"))
    twice = run(pair_problem("disjoint_ratio2_p1e-04_d4"))
    same = run(pair_problem("nested_r0_p1e-04_d4"))
    assert gate(half, 1.0).outcome == "pass"
    assert gate(twice, 1.0).outcome == "fail"
    verdict = gate(same, 1.0)
    assert verdict.outcome == "inconclusive"
    assert verdict.lower <= 1.0 < verdict.upper
    assert verdict.n_final_needed is None  # an estimate at the margin
    # a margin just above half's upper bound: more samples would decide it
    close = gate(half, half.ratio.upper * 0.99)
    assert close.outcome == "inconclusive"
    assert close.n_final_needed > half.a.n_samples


@pytest.mark.slow
def test_the_intervals_cover_over_seeds():
    """40 fixed seeds of an overlapping pair at the benchmark's budget: >= 35 cover."""
    pair = pair_problem("overlap_r0.3_p1e-04_d10")
    covers = {"a": 0, "b": 0, "difference": 0, "ratio": 0}
    truth = {
        "a": pair.p_a,
        "b": pair.p_b,
        "difference": pair.difference,
        "ratio": pair.ratio,
    }
    for seed in range(40):
        est = run(pair, seed=seed, n_particles=2000, n_final=10_000)
        for key in covers:
            lo, hi = getattr(est, key).ci
            covers[key] += lo <= truth[key] <= hi
    assert min(covers.values()) >= 35, covers
