import math

import numpy as np
import pytest

from avrisk.rare import FixedCovNormal, ScaledBeta, cross_entropy
from avrisk.rare.defensive import DefensiveMixture
from avrisk.testing import beta_sum_problem, check_estimator, gaussian_linear_problem

BASE = FixedCovNormal(np.zeros(2), cov=np.eye(2))
FAR = FixedCovNormal(np.array([4.0, -3.0]), cov=np.eye(2))


def test_weights_of_the_base_are_bounded_by_one_over_the_defensive_share():
    mix = DefensiveMixture(FAR, BASE, 0.2)
    x = mix.sample(50_000, np.random.default_rng(1))
    log_w = BASE.log_prob(x) - mix.log_prob(x)
    assert log_w.max() <= -math.log(0.2) + 1e-12
    # E_m[p0 / m] = 1, within 4 standard errors of the sample mean.
    w = np.exp(log_w)
    assert abs(w.mean() - 1.0) < 4 * w.std() / np.sqrt(w.size)


def test_the_mixture_draws_its_share_from_each_component_and_its_density_matches():
    mix = DefensiveMixture(FAR, BASE, 0.3)
    x = mix.sample(40_000, np.random.default_rng(2))
    near_far = np.linalg.norm(x - FAR.mean, axis=1) < np.linalg.norm(x, axis=1)
    share = 1.0 - near_far.mean()  # the components barely overlap
    assert share == pytest.approx(0.3, abs=4 * np.sqrt(0.3 * 0.7 / x.shape[0]) + 2e-3)
    expected = np.logaddexp(
        np.log(0.7) + FAR.log_prob(x[:5]), np.log(0.3) + BASE.log_prob(x[:5])
    )
    np.testing.assert_allclose(mix.log_prob(x[:5]), expected)


def test_a_sample_does_not_depend_on_how_many_are_drawn():
    mix = DefensiveMixture(
        ScaledBeta(7.0, 1.5, 80.0, 40.0), ScaledBeta(2, 2, 80, 40), 0.1
    )
    short = mix.sample(100, np.random.default_rng(3))
    long = mix.sample(1000, np.random.default_rng(3))
    np.testing.assert_array_equal(short, long[:100])


@pytest.mark.parametrize("weight", [0.0, 1.0, -0.1])
def test_a_share_outside_the_open_unit_interval_is_refused(weight):
    with pytest.raises(ValueError, match="weight"):
        DefensiveMixture(FAR, BASE, weight)


def test_cross_entropy_refuses_a_defensive_share_outside_zero_to_one():
    with pytest.raises(ValueError, match="defensive"):
        cross_entropy(lambda x: x[:, 0], BASE, 0.0, defensive=1.0)


@pytest.mark.parametrize(
    "problem",
    [gaussian_linear_problem(2, p=1e-6), beta_sum_problem(6, p=1e-5)],
    ids=lambda p: p.name,
)
def test_cross_entropy_with_a_defensive_final_stage_stays_exact_and_bounded(problem):
    batches = []

    def estimate(pr, seed):
        return cross_entropy(
            pr.f, pr.base, pr.gamma, rho=0.1, n_per_iter=2000, n_iter=8,
            n_final=20_000, seed=seed, defensive=0.1, on_batch=batches.append,
        )  # fmt: skip

    est = check_estimator(estimate, problem, seed=0)
    final = [b for b in batches if b.stage == 0]
    log_w = np.concatenate([b.log_p0 - b.log_q for b in final])
    assert log_w.max() <= -math.log(0.1) + 1e-9
    assert est.n_hits > 100  # 90% of the stage still comes from the proposal
