"""Subset simulation's error from its family tree: exact counts and coverage."""

import math

import numpy as np
import pytest
from scipy import stats

from avrisk.rare import subset_simulation
from avrisk.rare.splitting_genealogy import (
    family_tree_error,
    interval_quantile,
    satterthwaite_dof,
)
from avrisk.rare.splitting_levels import lognormal_interval
from avrisk.testing import gaussian_linear_problem
from avrisk.testing.suite import suite_problem

#: Set 0: six draws; three lie at or below its level 0.35 (draws 0, 2 and 5)
#: and seed, in that order, the three chains of set 1.
SET_0 = (np.array([[0.1], [0.5], [0.2], [0.9], [0.8], [0.3]]), 0.35, 0)


@pytest.mark.parametrize(
    ("chains", "cov_squared", "ancestors"),
    [
        # both hits (f <= 0.15) in chain 0: one family. Clusters of set 1
        # (3 chains, counts 2, 0, 0): 3/2 * 24/9 / 2^2 = 1, plus set 0's own
        # 0.25; of set 0 (6 draws, counts 2, 0, 0, 0, 0, 0): 6/5 * 30/9 / 4 = 1
        ([[0.1, 0.05], [0.2, 0.3], [0.3, 0.25]], 1.25, 1.0),
        # one hit in chain 0, one in chain 2: counts 1, 0, 1 give
        # 3/2 * 6/9 / 4 = 0.25 (+ 0.25); set 0's 1, 0, 0, 0, 0, 1 give
        # 6/5 * 12/9 / 4 = 0.4, narrower at the same degrees of freedom
        ([[0.1, 0.3], [0.2, 0.3], [0.3, 0.05]], 0.5, 2.0),
    ],
)
def test_the_error_is_the_widest_spread_of_the_hits_over_their_ancestors(
    chains, cov_squared, ancestors
):
    set_1 = np.array(chains)
    hits = set_1.ravel() <= 0.15
    tree = family_tree_error([SET_0, (set_1, 0.15, 0)], hits, level_cov=[0.25])
    assert tree.cov_squared == pytest.approx(cov_squared)
    assert tree.ancestors == pytest.approx(ancestors)
    assert tree.dof == 1.0  # a - 1, at least 1


def test_few_families_take_student_t_and_replicates_satterthwaite():
    assert interval_quantile(math.inf) == pytest.approx(stats.norm.ppf(0.975))
    assert interval_quantile(2.0) == pytest.approx(stats.t.ppf(0.975, 2))
    assert interval_quantile(30.0) < 1.05 * interval_quantile(math.inf)
    assert satterthwaite_dof([1.0, 1.0], [math.inf, math.inf]) == math.inf
    assert satterthwaite_dof([1.0, 1.0], [3.0, 3.0]) == pytest.approx(6.0)
    # a replicate of normal error adds variance, not doubt
    assert satterthwaite_dof([1.0, 3.0], [2.0, math.inf]) == pytest.approx(32.0)
    wide = lognormal_interval(1e-6, 0.1, dof=2.0)
    normal = lognormal_interval(1e-6, 0.1)
    assert wide[0] < normal[0] and wide[1] > normal[1]


def test_a_first_set_grown_on_a_plateau_is_not_a_cluster_and_no_hit_no_error():
    set_1 = np.array([[0.1, 0.05], [0.2, 0.3], [0.3, 0.25]])
    hits = set_1.ravel() <= 0.15
    grown = (SET_0[0], SET_0[1], 3)  # its first three draws are not counted
    tree = family_tree_error([grown, (set_1, 0.15, 0)], hits, level_cov=[0.0])
    assert tree.cov_squared == pytest.approx(1.0)  # set 1's chains only
    none = family_tree_error([SET_0, (set_1, 0.15, 0)], hits & False, [0.0])
    assert none == (0.0, math.inf, math.inf)


def _au_beck_interval(est):
    """The interval the levels' summed errors alone would give."""
    parts = zip(est.details["replicates"], est.details["level_cov"], strict=True)
    var = sum(r["p"] ** 2 * sum(c * c for c in covs) for r, covs in parts)
    se = math.sqrt(var) / len(est.details["replicates"])
    return lognormal_interval(est.p, (se / est.p) ** 2)


def _runs(problem, n_particles, seeds=40):
    return [
        subset_simulation(
            problem.f,
            problem.base,
            problem.gamma,
            seed=seed,
            n_particles=n_particles,
            directional_audit=False,
        )
        for seed in range(seeds)
    ]


def _covers(interval, p):
    return interval[0] <= p <= interval[1]


def test_two_regions_one_reached_through_few_particles_are_covered():
    """RP110: 99.1% of p in a region the levels reach through a few particles.

    How many of them a set holds is carried by every later level; Au & Beck's
    sum over levels does not see it (18 of these 40 intervals cover p), the
    family tree does (36), and its error is the runs' spread.
    """
    problem = suite_problem("RP110")
    runs = _runs(problem, 5200)
    p = problem.p_exact
    assert sum(_covers(e.ci, p) for e in runs) >= 32
    assert sum(_covers(_au_beck_interval(e), p) for e in runs) <= 24
    assert any("Student's t at" in e.main.interval for e in runs)
    spread = np.std([e.p for e in runs], ddof=1) / p
    reported = math.sqrt(np.mean([(e.stderr / e.p) ** 2 for e in runs]))
    assert 0.6 * spread < reported < 1.6 * spread


def test_without_a_pinch_the_family_tree_keeps_the_error_near_the_spread():
    problem = gaussian_linear_problem(10, p=1e-5)
    runs = _runs(problem, 2000)
    assert sum(_covers(e.ci, problem.p_exact) for e in runs) >= 36
    spread = np.std([e.p for e in runs], ddof=1) / problem.p_exact
    reported = math.sqrt(np.mean([(e.stderr / e.p) ** 2 for e in runs]))
    assert 0.7 * spread < reported < 1.5 * spread
    assert min(min(e.details["ancestors"]) for e in runs) > 2.0
