import json

import numpy as np
import pytest
from scipy import stats

from avrisk.rare import FixedCovNormal, ScaledBeta, naive_mc
from avrisk.testing import check_estimator, gaussian_linear_problem


def linear_f(x):
    return x[:, 0]


BASE = FixedCovNormal(np.zeros(1), cov=np.eye(1))


def test_naive_mc_agrees_with_the_exact_gaussian_tail():
    problem = gaussian_linear_problem(2, p=1e-2)
    check_estimator(
        lambda pr, s: naive_mc(pr.f, pr.base, pr.gamma, 100_000, seed=s), problem
    )


def test_zero_hits_report_p_zero_with_an_honest_upper_bound():
    est = naive_mc(linear_f, BASE, gamma=-10.0, n=1000)
    assert est.p == 0.0 and est.n_hits == 0
    low, high = est.ci
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** (1 / 1000))
    json.dumps(est.to_dict())


def test_every_test_threshold_is_estimated_from_the_same_samples():
    est = naive_mc(linear_f, BASE, gamma=-1.0, n=50_000, gamma_test=[-2.0, 0.0], seed=3)
    assert list(est.by_gamma) == [-1.0, -2.0, 0.0]
    hits = [est.by_gamma[g].n_hits for g in (-2.0, -1.0, 0.0)]
    assert hits == sorted(hits)  # nested events
    for g, item in est.by_gamma.items():
        assert abs(item.p - stats.norm.cdf(g)) < 5 * item.stderr


def test_same_seed_gives_the_same_result_whatever_the_batch_size():
    runs = [
        naive_mc(linear_f, BASE, 0.5, 1001, seed=9, batch_size=b)
        for b in (None, 1000, 7)
    ]
    assert len({r.p for r in runs}) == 1


def test_nan_from_f_is_an_error_naming_the_row():
    def f(x):
        out = x[:, 0].copy()
        out[5] = np.nan
        return out

    with pytest.raises(ValueError, match="NaN for 1 of 100 samples.*row 5"):
        naive_mc(f, BASE, 0.0, 100)


def test_f_returning_the_wrong_shape_is_an_error():
    with pytest.raises(ValueError, match=r"shape \(10,\).*got shape \(10, 1\)"):
        naive_mc(lambda x: x, BASE, 0.0, 10)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(n=0), "n_final: Input should be greater than or equal to 1"),
        (dict(n=10, seed=-1), "seed"),
        (dict(n=10, batch_size=0), "batch_size"),
        (dict(n=10, interval="exact"), "interval"),
    ],
)
def test_bad_arguments_are_rejected_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        naive_mc(linear_f, BASE, 0.0, **kwargs)


def test_a_non_family_base_is_rejected():
    with pytest.raises(TypeError, match="avrisk.rare family"):
        naive_mc(linear_f, stats.norm(), 0.0, 10)


@pytest.mark.slow
@pytest.mark.parametrize("interval", ["clopper-pearson", "wilson"])
def test_binomial_intervals_cover_the_truth_at_the_nominal_rate(interval):
    base = ScaledBeta(2.0, 2.0)
    p_true = stats.beta(2, 2).cdf(0.1)  # 0.028
    reps = 400
    covered = 0
    for seed in range(reps):
        est = naive_mc(lambda x: x[:, 0], base, 0.1, 300, seed=seed, interval=interval)
        covered += est.ci[0] <= p_true <= est.ci[1]
    # coverage >= 95% nominal; allow 4 binomial standard deviations below it
    assert covered / reps >= 0.95 - 4 * np.sqrt(0.95 * 0.05 / reps)
