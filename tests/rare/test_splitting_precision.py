"""An imprecise levels' answer takes more replicates (rare.splitting_precision)."""

import math
import warnings

import numpy as np
import pytest

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare import splitting_is
from avrisk.rare.estimator import get_estimator
from avrisk.rare.results import GammaEstimate
from avrisk.rare.splitting_importance import SplittingImportanceSampling
from avrisk.rare.splitting_levels import Z_CONFIDENCE
from avrisk.rare.splitting_precision import PRECISE_LOG_SE, imprecise
from avrisk.testing import gaussian_linear_problem
from avrisk.testing.generated import k_region_problem
from tests.interrupts import ctrl_c_when, without_wall_time

#: Ten regions in 50 dimensions at 600 particles: the proposal cannot hold
#: them, the levels answer, to within a factor of about 2.
TEN_REGIONS = k_region_problem(10, 50, p=1e-7)
SMALL = {"n_particles": 600, "n_final": 2000, "directional_audit": False}


def run(problem, seed=0, **settings):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return splitting_is(
            problem.f, problem.base, problem.gamma, seed=seed, **settings
        )


def estimate(p, upper):
    return GammaEstimate(
        gamma=0.0, p=p, stderr=0.0, ci=(0.0, upper), n_hits=10, ess=10.0, n_samples=100
    )


def with_interval(half_width_in_log):
    return estimate(1e-6, 1e-6 * math.exp(half_width_in_log))


def test_imprecise_is_an_interval_wider_than_three_errors_in_a_factor_of_two():
    edge = Z_CONFIDENCE * PRECISE_LOG_SE
    assert PRECISE_LOG_SE == pytest.approx(math.log(2) / 3)
    assert imprecise(with_interval(edge * 1.01))
    assert not imprecise(with_interval(edge * 0.99))
    assert not imprecise(estimate(0.0, 1e-3))  # a bound


def test_an_imprecise_levels_answer_takes_as_many_replicates_again():
    added = run(TEN_REGIONS, **SMALL)
    without = run(TEN_REGIONS, **SMALL, more_replicates=False)
    details = added.details
    assert details["answer"] == without.details["answer"] == "splitting"
    assert details["replicates_added"] == 2  # as many as planned, no more
    assert "replicates_added" not in without.details
    assert len(details["replicates"]) == 4 and len(without.details["replicates"]) == 2
    # the planned replicates are the same draws; the added ones come after them
    assert details["replicates"][:2] == without.details["replicates"]
    ps = [r["p"] for r in details["replicates"]]
    assert added.p == pytest.approx(np.mean(ps), rel=1e-12)
    assert added.n_evals > without.n_evals
    # their mean is more precise: its interval is narrower
    assert math.log(added.ci[1] / added.ci[0]) < math.log(without.ci[1] / without.ci[0])


def test_the_added_replicates_stay_within_max_calls():
    # at this cap one replicate more fits, at its most, beside the final stage
    method = get_estimator("splitting_is", n_particles=600, n_final=2000)
    cap = method.settings.bound(regrow=0)
    one = run(TEN_REGIONS, **SMALL, max_calls=cap)
    assert one.details["replicates_added"] == 1
    assert one.n_evals <= cap


def test_a_precise_or_sampled_answer_takes_none():
    sampled = run(gaussian_linear_problem(20, p=1e-6), n_particles=1000)
    assert sampled.details["answer"] == "importance_sampling"
    assert "replicates_added" not in sampled.details


def test_a_run_interrupted_in_the_added_replicates_resumes_to_the_same_summary(
    tmp_path,
):
    columns = [f"x{i}" for i in range(TEN_REGIONS.base.dim)]
    settings = RunSettings(
        "splitting_is", gamma=0.0, seed=0, n_particles=600, n_final=2000
    )

    def in_directory(path, f=TEN_REGIONS.f):
        directory = RunDirectory(path, columns)
        return run_estimation(directory, TEN_REGIONS.base, f, settings)

    reference = in_directory(tmp_path / "reference")
    before = run(TEN_REGIONS, **SMALL, more_replicates=False).n_evals - 2000
    # in the first replicate added
    interrupted, _ = ctrl_c_when(TEN_REGIONS.f, lambda rows: sum(rows) > before + 1000)
    with pytest.raises(KeyboardInterrupt):
        in_directory(tmp_path / "run", f=interrupted)
    resumed = in_directory(tmp_path / "run")
    assert resumed["estimate"]["details"]["replicates_added"] == 2
    assert without_wall_time(resumed["estimate"]) == without_wall_time(
        reference["estimate"]
    )


def test_the_cross_check_table_says_why_the_replicates_were_added():
    estimate = run(TEN_REGIONS, **SMALL).to_dict()
    (note,) = [
        t.note
        for t in SplittingImportanceSampling.diagnostics(estimate)
        if t.title.startswith("Importance sampling vs")
    ]
    assert "the mean of 4 replicates, 2 of them run after the fit" in note
