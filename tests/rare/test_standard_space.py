"""CE proposals in the base's standard-normal space (StandardSpaceShift)."""

import json
import warnings

import numpy as np
import pytest

from avrisk.rare import (
    FixedCovNormal,
    Product,
    ScaledBeta,
    StandardSpaceShift,
    cross_entropy,
)
from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.families.standard_space_normal import (
    VARIANCE_RANGE,
    StandardSpaceNormal,
)
from avrisk.rare.mixture import mixture_ce
from avrisk.rare.mixture_em import MixtureProposal
from avrisk.rare.proposals import proposal_from_record, proposal_record
from avrisk.testing import beta_sum_problem, check_family, four_branch_problem


@pytest.fixture
def base():
    """Two Betas and a correlated 2-d normal that CE may not move (box 0)."""
    cov = np.array([[1.0, 0.5], [0.5, 2.0]])
    return Product(
        [
            ScaledBeta(2.0, 2.0, lo=80.0, scale=40.0, bounds=(1.0, 3.9)),
            ScaledBeta(2.0, 3.0, lo=0.0, scale=9.0, bounds=(1.0, 3.9)),
            FixedCovNormal(np.zeros(2), cov=cov, max_shift=0.0),
        ]
    )


def test_at_zero_shift_the_family_is_the_base(base):
    x = base.sample(500, np.random.default_rng(0))
    q = StandardSpaceShift(base)
    np.testing.assert_allclose(q.log_prob(x), base.log_prob(x), atol=1e-12)
    np.testing.assert_array_equal(q.searched, [True, True, False, False])


def test_weights_are_the_closed_form_and_average_one(base):
    q = StandardSpaceShift(base).project(np.array([2.5, -1.5, 0.0, 0.0]))
    x = q.sample(50_000, np.random.default_rng(1))
    z = base.to_standard_normal(x)
    log_w = base.log_prob(x) - q.log_prob(x)
    mu = q.mean
    np.testing.assert_allclose(log_w, -z @ mu + 0.5 * mu @ mu, atol=1e-9)
    w = np.exp(log_w)
    assert abs(w.mean() - 1.0) < 4 * w.std() / np.sqrt(w.size)
    # the mean parameter is E_q[T(X)] = mu, within its standard error (1/sqrt n)
    assert np.all(np.abs(z.mean(axis=0) - mu) < 4 / np.sqrt(z.shape[0]))


def test_project_keeps_unsearched_coordinates_and_clips_the_rest(base):
    q = StandardSpaceShift(base, max_shift=3.0).project(np.array([5.0, -1.0, 2, 2]))
    np.testing.assert_array_equal(q.mean, [3.0, -1.0, 0.0, 0.0])
    assert q.in_search_box()
    assert not StandardSpaceShift(base, [0.0, 0.0, 1.0, 0.0]).in_search_box()
    with pytest.raises(ValueError, match="finite"):
        q.project(np.array([np.nan, 0, 0, 0]))


def test_samples_are_prefix_consistent(base):
    q = StandardSpaceShift(base, [1.0, 2.0, 0.0, 0.0])
    long = q.sample(50, np.random.default_rng(3))
    np.testing.assert_array_equal(q.sample(20, np.random.default_rng(3)), long[:20])


@pytest.mark.parametrize("kind", ["family", "defensive", "mixture"])
def test_records_draw_the_same_samples_again(base, kind):
    near = StandardSpaceShift(base, [2.0, -1.0, 0.0, 0.0])
    far = StandardSpaceShift(base, [-1.0, 3.0, 0.0, 0.0])
    proposal = {
        "family": near,
        "defensive": DefensiveMixture(near, base, 0.1),
        "mixture": MixtureProposal([near, far], [0.3, 0.7], base, 0.1),
    }[kind]
    record = proposal_record(proposal, base)
    assert record is not None and record["space"] == "standard"
    again = proposal_from_record(record, base)
    rng = np.random.default_rng
    np.testing.assert_array_equal(again.sample(64, rng(5)), proposal.sample(64, rng(5)))
    x = proposal.sample(64, rng(6))
    np.testing.assert_array_equal(again.log_prob(x), proposal.log_prob(x))


def test_a_record_of_an_unknown_space_is_refused(base):
    record = {"kind": "family", "space": "polar", "params": [0.0] * 4}
    with pytest.raises(ValueError, match="unknown space"):
        proposal_from_record(record, base)


def _relative_errors(problem, space, seeds, **settings):
    """``(p_hat / p - 1) / (se / p)`` and ``se / p`` per seed."""
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in seeds:
            est = cross_entropy(
                problem.f, problem.base, problem.gamma, seed=seed, space=space,
                **settings,
            )  # fmt: skip
            out.append((est.p - problem.p_exact) / est.stderr)
            out.append(est.stderr / est.p)
    return np.array(out[0::2]), np.array(out[1::2])


def test_standard_space_ce_is_exact_and_beats_the_boxed_betas_at_1e_8():
    """Six Beta(2, 2) in the bundled scenarios' box [1, 3.9]: p = 1e-8, exact.

    The boxed Beta proposals cannot concentrate on the corner; the shifted
    standard normals can, with weights of finite variance. Same budget, same
    seeds: every standard-space estimate within 4 of its own standard errors
    of the exact p, and its relative standard error at most half the boxed one.
    """
    problem = beta_sum_problem(6, p=1e-8, bounds=(1.0, 3.9))
    settings = dict(rho=0.1, n_per_iter=1000, n_iter=8, n_final=8000)
    z_std, rel_std = _relative_errors(problem, "standard", range(3), **settings)
    _, rel_nat = _relative_errors(problem, "natural", range(3), **settings)
    assert np.all(np.abs(z_std) < 4), z_std
    assert np.median(rel_std) < 0.5 * np.median(rel_nat), (rel_std, rel_nat)


def test_mixture_ce_in_standard_space_finds_every_branch():
    problem = four_branch_problem()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = mixture_ce(
            problem.f, problem.base, problem.gamma, n_per_iter=2000, n_iter=6,
            n_final=20_000, seed=0, space="standard",
        )  # fmt: skip
    assert abs(est.p - problem.p_exact) < 4 * est.stderr
    assert est.stderr / est.p < 0.05


@pytest.fixture
def scaled(base):
    """A member that shifts and narrows the Betas' standard normals."""
    return StandardSpaceNormal(base).project(
        np.array([2.0, -1.0, 0.0, 0.0, 4.0 + 0.7, 1.0 + 1.5, 1.0, 1.0])
    )


def test_the_scaled_family_passes_the_conformance_check(scaled, rng):
    check_family(scaled, rng)


def test_the_scaled_family_at_unit_variance_is_the_shift(base):
    shift = StandardSpaceShift(base, [2.0, -1.0, 0.0, 0.0])
    scaled = StandardSpaceNormal.of_shift(shift)
    x = shift.sample(200, np.random.default_rng(2))
    np.testing.assert_allclose(scaled.log_prob(x), shift.log_prob(x), atol=1e-10)
    np.testing.assert_array_equal(
        scaled.sample(50, np.random.default_rng(3)),
        shift.sample(50, np.random.default_rng(3)),
    )


def test_scaled_weights_are_the_closed_form_and_average_one(scaled, base):
    x = scaled.sample(50_000, np.random.default_rng(1))
    z = base.to_standard_normal(x)
    mu, v = scaled.mean, scaled.variance
    np.testing.assert_allclose(scaled.variance, [0.7, 1.5, 1.0, 1.0], rtol=1e-12)
    log_normal_ratio = (-0.5 * (z - mu) ** 2 / v - 0.5 * np.log(v) + 0.5 * z * z).sum(1)
    np.testing.assert_allclose(
        base.log_prob(x) - scaled.log_prob(x), -log_normal_ratio, atol=1e-9
    )
    w = np.exp(base.log_prob(x) - scaled.log_prob(x))
    assert abs(w.mean() - 1.0) < 4 * w.std() / np.sqrt(w.size)


def test_scaled_projection_clips_variances_and_keeps_unsearched_coordinates(base):
    low, high = VARIANCE_RANGE
    m = np.array([1.0, 0.0, 3.0, 0.0, 1.0 + 0.01, 100.0, 9.0 + 0.2, 5.0])
    q = StandardSpaceNormal(base).project(m)
    np.testing.assert_array_equal(q.mean, [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(q.variance, [low, high, 1.0, 1.0])
    assert q.in_search_box()
    with pytest.raises(ValueError, match="positive"):
        StandardSpaceNormal(base, variance=[1.0, 0.0, 1.0, 1.0])


def test_a_scaled_mixture_record_draws_the_same_samples_again(scaled, base):
    other = StandardSpaceNormal(base, [-1.0, 3.0, 0.0, 0.0], [1.2, 0.8, 1.0, 1.0])
    mixture = MixtureProposal([scaled, other], [0.3, 0.7], base, 0.1)
    record = proposal_record(mixture, base)
    assert record is not None and record["space"] == "standard-scaled"
    again = proposal_from_record(json.loads(json.dumps(record)), base)
    rng = np.random.default_rng
    np.testing.assert_array_equal(again.sample(64, rng(5)), mixture.sample(64, rng(5)))
    x = mixture.sample(64, rng(6))
    np.testing.assert_array_equal(again.log_prob(x), mixture.log_prob(x))
    # variances that are not positive, from an untrusted record, are refused
    record["components"][0][base.dim] = -1.0
    with pytest.raises(ValueError, match="variances must be positive"):
        proposal_from_record(record, base)
