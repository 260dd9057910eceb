"""``benchmarks/ab_scenario.py``'s bookkeeping: resume, duplicates, the summary."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location(
        "ab_scenario", ROOT / "benchmarks" / "ab_scenario.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _record(seed: int, diff: float, indep: float, outcome: str) -> dict:
    part = {"value": 1e-4, "ci": [0.9e-4, 1.1e-4]}
    return {
        "seed": seed,
        "paired": {
            "a": part,
            "b": {**part, "value": 1e-4 + diff},
            "difference": {"value": diff},
            "r": 0.2,
            "n_evals": 1000,
            "outcome": outcome,
            "trust": "ok",
        },
        "independent": {"a": 1e-4, "b": 1e-4 + indep, "n_evals": 1900},
    }


def test_summary_spreads_outcomes_and_duplicates(bench, tmp_path):
    rng = np.random.default_rng(0)
    paired = rng.normal(3e-5, 1e-6, 8)
    indep = rng.normal(3e-5, 4e-6, 8)
    recs = [_record(s, paired[s], indep[s], "fail") for s in range(8)]
    recs[3]["paired"]["outcome"] = "inconclusive"
    # a seed run twice (two processes crossed): the first line counts
    recs.append(_record(0, 1.0, 1.0, "pass"))
    path = tmp_path / "runs.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    row, md = bench.summary(path)
    assert row["seeds"] == 8
    assert row["spread_paired"] == pytest.approx(paired.std(ddof=1))
    assert row["spread_independent"] == pytest.approx(indep.std(ddof=1))
    assert row["narrower_by"] == pytest.approx(indep.std(ddof=1) / paired.std(ddof=1))
    assert row["outcomes"] == {"pass": 0, "fail": 7, "inconclusive": 1}
    assert row["rollouts_paired"] == 2000 and row["rollouts_independent"] == 1900
    assert "| 0 / 7 / 1 |" in md
    assert "spread_even" not in row  # no even runs: no comparison at equal rollouts
    # the even paired runs (half the samples, both egos): compared at equal rollouts
    even_diff = rng.normal(3e-5, 2e-6, 5)
    even = tmp_path / "even.jsonl"
    even.write_text(
        "".join(
            json.dumps(
                {"seed": s, "paired": {"difference": {"value": d}, "n_evals": 950}}
            )
            + "\n"
            for s, d in enumerate(even_diff)
        )
    )
    row, md = bench.summary(path, even)
    assert row["even_seeds"] == 5
    assert row["narrower_by_even"] == pytest.approx(
        indep.std(ddof=1) / even_diff.std(ddof=1)
    )
    assert row["rollouts_even"] == 1900 == row["rollouts_independent"]
    assert "At equal rollouts" in md


def test_run_skips_seeds_already_recorded(bench, tmp_path, monkeypatch):
    path = tmp_path / "runs.jsonl"
    path.write_text(json.dumps(_record(1, 0.0, 0.0, "pass")) + "\n")
    ran = []
    monkeypatch.setattr(
        bench,
        "paired_record",
        lambda seed, scratch: (
            ran.append(seed)
            or {"outcome": "pass", "ratio": {"value": 1.0}, "seconds": 0.0}
        ),
    )
    monkeypatch.setattr(
        bench, "independent_record", lambda seed, scratch: {"seconds": 0.0}
    )
    bench.run([2, 1, 0], path)
    assert ran == [2, 0]
    assert sorted(bench._done(path)) == [0, 1, 2]
