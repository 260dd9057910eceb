"""A rollout's start and drivers as percentiles of P0, and the failures' ranking."""

import numpy as np
import pytest

from avrisk.assembly import Typicality, base_distribution, scenario_typicality
from avrisk.rare import FixedCovNormal, Product, ScaledBeta
from avrisk.scenario import load_spec


@pytest.fixture(scope="module")
def learned():
    spec = load_spec("highway_default")
    return scenario_typicality(spec), base_distribution(spec)


def _percentiles(typical, base, x):
    return typical.percentiles(x[:, : typical.n_situation], base.log_prob(x))


def test_draws_of_p0_are_spread_evenly_over_both_percentiles(learned):
    typical, base = learned
    assert typical.columns[:2] == ("veh0.s", "veh0.t") and typical.drivers_dim == 404
    x = base.sample(4000, np.random.default_rng(1))  # not the reference's seed
    for share in _percentiles(typical, base, x):
        assert ((0.0 <= share) & (share <= 100.0)).all()
        # a percentile of P0 among P0's own draws is uniform on [0, 100]
        assert np.mean(share < 10.0) == pytest.approx(0.1, abs=0.025)
        assert np.median(share) == pytest.approx(50.0, abs=5.0)


def test_the_mode_is_at_100_and_a_start_at_the_edge_near_0(learned):
    typical, base = learned
    x = base.sample(2, np.random.default_rng(2))
    starts = typical.situation.blocks
    x[0, typical.n_situation :] = base.blocks[len(starts)].mean  # the drivers' mode
    x[1, : typical.n_situation] = [b.lo + 1e-3 * b.scale for b in starts]
    share = _percentiles(typical, base, x)
    assert share.drivers[0] == 100.0
    assert share.situation[1] == 0.0  # every coordinate at the edge of its range


def test_a_scenario_without_learned_drivers_has_one_percentile():
    typical = scenario_typicality(load_spec("highway_idm"))
    base = base_distribution(load_spec("highway_idm"))
    x = base.sample(5, np.random.default_rng(0))
    share = _percentiles(typical, base, x)
    assert share.drivers is None and share.situation.shape == (5,)
    key = typical.rank(x[:, : typical.n_situation], base.log_prob(x))
    np.testing.assert_array_equal(key[:, 0], share.situation)


def test_failures_rank_by_their_lower_percentile_then_by_log_p0():
    base = Product(
        [ScaledBeta(2, 2, lo=0.0, scale=1.0), FixedCovNormal([0.0], cov=[[1.0]])]
    )
    typical = Typicality(base, ["s"], n_reference=1000)
    x = np.array([[0.5, 3.0], [0.001, 0.0], [0.5, 0.1], [0.0005, 0.0]])
    key = typical.rank(x[:, :1], base.log_prob(x))
    share = _percentiles(typical, base, x)
    np.testing.assert_array_equal(key[:, 0], np.minimum(*share))
    assert share.situation[1] == share.situation[3] == 0.0  # below every draw
    order = np.lexsort(-key.T[::-1])
    # a typical start with typical drivers first; an unusual driver (3 sd)
    # after; the two starts below every reference draw last, by log p0
    assert order.tolist() == [2, 0, 1, 3]


def test_percentiles_are_deterministic():
    spec = load_spec("highway_idm")
    a, b = scenario_typicality(spec), scenario_typicality(spec)
    np.testing.assert_array_equal(a.reference, b.reference)


def test_the_drivers_must_be_normal_and_the_start_whole_blocks():
    beta = ScaledBeta(2, 2, lo=0.0, scale=1.0)
    with pytest.raises(TypeError, match="normal"):
        Typicality(Product([beta, beta]), ["s"])
    normal = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    with pytest.raises(ValueError, match="no block"):
        Typicality(Product([beta, normal]), ["s", "xi.0"])
