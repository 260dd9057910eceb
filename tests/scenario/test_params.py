"""Flat X <-> named scenario parameters and the base distribution P0."""

import numpy as np
import pytest
from scipy import stats

from avrisk.rare import Product, ScaledBeta
from avrisk.scenario import (
    VEHICLE_FIELDS,
    ParamLayout,
    ScenarioParams,
    build_base_distribution,
    load_spec,
    spec_from_dict,
)


@pytest.fixture(scope="module")
def spec():
    return load_spec("highway_idm")


def test_the_layout_names_columns_vehicle_by_vehicle_then_xi():
    layout = ParamLayout(n_vehicles=3, xi_dim=2)
    assert layout.dim == 14
    assert layout.columns[:4] == ("veh0.s", "veh0.t", "veh0.heading", "veh0.speed")
    assert layout.columns[-3:] == ("veh2.speed", "xi.0", "xi.1")
    assert layout.index("veh2.t") == 9
    assert list(layout.field_columns("speed")) == [3, 7, 11]
    assert layout.unit("veh1.heading") == "deg" and layout.unit("xi.1") == "-"
    with pytest.raises(KeyError, match="veh9.s"):
        layout.index("veh9.s")


@pytest.mark.parametrize("xi_dim", [0, 5])
def test_flat_x_round_trips_through_named_parameters(xi_dim):
    layout = ParamLayout(n_vehicles=6, xi_dim=xi_dim)
    x = np.random.default_rng(0).normal(size=(7, layout.dim))
    params = ScenarioParams.from_flat(x, layout)
    assert params.speed.shape == (7, 6) and params.xi.shape == (7, xi_dim)
    assert params.speed[2, 3] == x[2, layout.index("veh3.speed")]
    np.testing.assert_array_equal(params.to_flat(), x)
    again = ScenarioParams.from_columns(params.to_columns(), layout)
    np.testing.assert_array_equal(again.to_flat(), x)
    np.testing.assert_array_equal(params[[4, 1]].to_flat(), x[[4, 1]])


def test_a_flat_x_of_the_wrong_width_is_refused():
    with pytest.raises(ValueError, match=r"\(B, 24\)"):
        ScenarioParams.from_flat(np.zeros((2, 23)), ParamLayout(6))
    with pytest.raises(KeyError, match="veh0.s"):
        ScenarioParams.from_columns({}, ParamLayout(1))


def test_p0_is_a_product_of_one_scaled_beta_per_coordinate(spec):
    p0 = build_base_distribution(spec)
    layout = ParamLayout.from_spec(spec)
    assert isinstance(p0, Product) and p0.dim == layout.dim == 24
    assert all(isinstance(b, ScaledBeta) for b in p0.blocks)
    speed3 = p0.blocks[layout.index("veh3.speed")]
    assert (speed3.lo, speed3.scale, speed3.bounds) == (10.0, 10.0, (1.0, 3.9))


def test_p0_has_the_papers_marginals(spec):
    # Sample means against exact Beta means; 5 sigma per coordinate keeps the
    # false-failure rate of the 24 checks below 1.5e-5 (fixed seed anyway).
    n = 20_000
    x = build_base_distribution(spec).sample(n, np.random.default_rng(12345))
    layout = ParamLayout.from_spec(spec)
    for j in range(spec.n_vehicles):
        ic = spec.initial_for(j)
        for name in VEHICLE_FIELDS:
            m = getattr(ic, name)
            col = x[:, layout.index(f"veh{j}.{name}")]
            assert m.lo <= col.min() and col.max() <= m.hi
            assert abs(col.mean() - m.mean) < 5 * np.sqrt(m.variance / n)
    # And one full-distribution check: veh0.speed is 10 Beta(2,2) + 10.
    u = (x[:, layout.index("veh0.speed")] - 10.0) / 10.0
    assert stats.kstest(u, stats.beta(2, 2).cdf).pvalue > 1e-4


def test_log_p0_is_the_sum_of_the_papers_beta_log_densities(spec):
    p0 = build_base_distribution(spec)
    x = p0.sample(5, np.random.default_rng(1))
    expected = np.zeros(5)
    for j in range(spec.n_vehicles):
        for name in VEHICLE_FIELDS:
            m = getattr(spec.initial_for(j), name)
            col = x[:, ParamLayout.from_spec(spec).index(f"veh{j}.{name}")]
            expected += stats.beta(m.a, m.b, loc=m.lo, scale=m.scale).logpdf(col)
    np.testing.assert_allclose(p0.log_prob(x), expected, rtol=1e-10)


def test_per_slot_overrides_reach_p0():
    spec = spec_from_dict(
        {
            "name": "o",
            "vehicles": [
                {"lane": 0},
                {"lane": 1, "initial": {"speed": {"lo": 3.0, "scale": 1.0}}},
            ],
        }
    )
    p0 = build_base_distribution(spec)
    blk = p0.blocks[ParamLayout.from_spec(spec).index("veh1.speed")]
    assert (blk.lo, blk.scale) == (3.0, 1.0)
