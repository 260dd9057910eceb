"""benchmarks/initial_conditions.py: P0's starts against the I-80 pairs.

A small run (4,000 draws of P0, 10 pair resamples) checks the output's
structure and that the starts it compares are P0's: the sampled speed
quantiles match the spec's scaled-Beta marginals' exact quantiles, and the
ego's gap to the slot ahead has the median its slot geometry gives, both
within four standard errors of a sample quantile.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import special, stats

from avrisk.scenario import load_spec

ROOT = Path(__file__).resolve().parents[2]
N_P0 = 4000


def _load_benchmark():
    spec = importlib.util.spec_from_file_location(
        "initial_conditions", ROOT / "benchmarks" / "initial_conditions.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def bench():
    return _load_benchmark()


@pytest.fixture(scope="module")
def run(bench, tmp_path_factory):
    out = tmp_path_factory.mktemp("ic") / "ic.json"
    argv = ["--n", str(N_P0), "--seed", "3", "--boot", "10", "--out", str(out)]
    result = bench.main(argv)
    return result, json.loads(out.read_text())


def _quantile_se(q: float, n: int, density: float) -> float:
    """Standard error of the sample q-quantile: sqrt(q (1 - q) / n) / f(x_q)."""
    return float(np.sqrt(q * (1 - q) / n) / density)


def test_structure_and_sets(run):
    result, written = run
    assert written == json.loads(json.dumps(result))
    assert result["scenario"] == "highway_default"
    expected = {
        f"{kind}.{who}"
        for kind in ("gap", "headway", "closing", "ttc")
        for who in ("ego", "behind")
    }
    expected |= {f"speed.{r}" for r in ("ego", "ahead", "behind", "left1", "right1")}
    expected |= {"speed.left2", "offset.left1", "offset.right1", "offset.left2"}
    assert set(result["p0"]) == expected
    rows = result["data_rows"]
    periods, bands = ["16:00-16:15", "17:00-17:15"], ["congested", "flowing"]
    assert list(rows) == ["all", *periods, *bands, "ego_speeds"]
    assert sum(rows[p] for p in periods) == sum(rows[b] for b in bands) == rows["all"]
    assert 0 < rows["ego_speeds"] < rows["flowing"]
    for q, per_set in result["comparison"].items():
        assert set(per_set) == set(rows), q
        lo, hi = per_set["all"]["ks_95"]
        assert 0 <= lo <= hi <= 1, q
        for c in per_set.values():
            assert 0 <= c["ks"] <= 1
            for side in ("p0_covers_data", "data_covers_p0"):
                assert 0 <= c[side]["range"] <= 1 and 0 <= c[side]["mass"] <= 1
    for values in result["p0"].values():
        cut = [values[f"p{k}"] for k in (5, 25, 50, 75, 95)]
        assert cut == sorted(cut)


def test_p0_speed_quantiles_match_the_beta_marginals(run):
    result, _ = run
    spec = load_spec("highway_default")
    for role, slot in (("ego", 0), ("ahead", 1)):
        m = spec.initial_for(slot).speed
        beta = stats.beta(m.a, m.b, loc=m.lo, scale=m.scale)
        got = result["p0"][f"speed.{role}"]
        assert got["n"] == N_P0
        for k in (5, 25, 50, 75, 95):
            exact = beta.ppf(k / 100)
            se = _quantile_se(k / 100, N_P0, beta.pdf(exact))
            assert abs(got[f"p{k}"] - exact) < 4 * se, (role, k, got, exact)


def test_ego_gap_median_is_the_slot_geometry(run):
    """Gap = 50 + S1 - S0 - 4.8 [m], S = 80 + 40 Beta(2, 2): median 45.2 m.

    The difference of two Beta(2, 2) has density 36 B(3, 3) = 1.2 at 0, so
    the gap's density at its median is 1.2 / 40 per metre.
    """
    result, _ = run
    spec = load_spec("highway_default")
    ego, ahead = spec.vehicles[0], spec.vehicles[1]
    assert spec.initial_for(0).s == spec.initial_for(1).s
    s = spec.initial_for(0).s
    assert (s.a, s.b) == (2.0, 2.0)
    median = ahead.offset - ego.offset - 0.5 * (ahead.length + ego.length)
    density = 36 * special.beta(3, 3)  # int_0^1 (6 b (1 - b))^2 db
    se = _quantile_se(0.5, N_P0, density / s.scale)
    assert abs(result["p0"]["gap.ego"]["p50"] - median) < 4 * se


def test_tables_have_a_row_per_quantity(bench, run):
    result, _ = run
    ks = bench.ks_table(result).splitlines()
    assert len(ks) == 2 + len(result["p0"])
    assert all(len(line) <= 88 for line in ks)
    rows = bench.quantile_table(result).splitlines()
    assert len(rows) == 2 + len(result["p0"]) + 6 * len(result["data"]["all"])
