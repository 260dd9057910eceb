"""``benchmarks/marginal_p_spread.py``'s variants: only the traffic's speeds differ."""

import importlib.util
from pathlib import Path

import pytest
from scipy import stats

from avrisk.scenario import load_spec, spec_from_dict

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location(
        "marginal_p_spread", ROOT / "benchmarks" / "marginal_p_spread.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_variants_change_the_traffic_speeds_only(bench):
    shipped = load_spec("highway_default").model_dump(mode="json")
    for name, (lo, scale) in bench.VARIANTS.items():
        variant = bench.variant_spec(name)
        spec = spec_from_dict(variant)  # a valid scenario
        assert spec.initial_conditions.speed.lo == lo
        assert spec.initial_conditions.speed.scale == scale
        # the slow vehicle keeps its own marginal, everything else is shipped
        assert variant["vehicles"] == shipped["vehicles"]
        rest = {
            k: v for k, v in variant.items() if k not in ("name", "initial_conditions")
        }
        assert rest == {
            k: v for k, v in shipped.items() if k not in ("name", "initial_conditions")
        }
        others = dict(variant["initial_conditions"], speed=None)
        assert others == dict(shipped["initial_conditions"], speed=None)
        assert (variant["name"] == shipped["name"]) == (name == "paper")


def test_stated_percentiles_are_the_marginals(bench):
    # the docstring's p5 / p50 / p95 of each variant, from Beta(2, 2)'s quantiles
    stated = {
        "paper": (11.35, 15.0, 18.65),
        "flowing": (5.15, 8.25, 11.35),
        "ego_speeds": (10.31, 12.5, 14.69),
    }
    for name, (lo, scale) in bench.VARIANTS.items():
        got = lo + scale * stats.beta.ppf([0.05, 0.5, 0.95], 2, 2)
        assert got == pytest.approx(stated[name], abs=0.006)
