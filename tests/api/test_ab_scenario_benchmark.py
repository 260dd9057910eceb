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


def _lines(path, recs):
    path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return path


def test_summary_spreads_outcomes_and_duplicates(bench, tmp_path):
    rng = np.random.default_rng(0)
    paired = rng.normal(3e-5, 1e-6, 8)
    indep = rng.normal(3e-5, 4e-6, 8)
    recs = [_record(s, paired[s], indep[s], "fail") for s in range(8)]
    recs[3]["paired"]["outcome"] = "inconclusive"
    recs[5]["paired"]["trust"] = "caution"
    # a seed run twice (two processes crossed): the first line counts
    recs.append(_record(0, 1.0, 1.0, "pass"))
    path = _lines(tmp_path / "runs.jsonl", recs)
    row, md = bench.summary(path)
    assert row["seeds"] == 8 and row["caution"] == 1
    assert row["outcomes"] == {"pass": 0, "fail": 7, "inconclusive": 1}
    assert "pass / fail / inconclusive 0 / 7 / 1" in md
    assert row["comparisons"] == []  # neither single nor even runs: no row
    # two default single runs per seed: the comparison at the default budget
    single = rng.normal(3e-5, 3e-6, 6)
    singles = _lines(
        tmp_path / "single.jsonl",
        [
            {"seed": s, "single": {"a": 1e-4, "b": 1e-4 + d, "n_evals": 2100}}
            for s, d in enumerate(single)
        ],
    )
    # the even paired runs (half the samples, both egos) against the
    # independent runs at half the settings, in ``results`` and a file of their own
    even_diff = rng.normal(3e-5, 2e-6, 5)
    even = _lines(
        tmp_path / "even.jsonl",
        [
            {"seed": s, "paired": {"difference": {"value": d}, "n_evals": 950,
                                   "trust": "ok"}}
            for s, d in enumerate(even_diff)
        ],
    )  # fmt: skip
    more = _lines(
        tmp_path / "independent.jsonl",
        [{"seed": 9, "independent": {"a": 1e-4, "b": 1.3e-4, "n_evals": 1900}}],
    )
    row, md = bench.summary(path, even, more, singles)
    default, at_half = row["comparisons"]
    assert default["seeds_paired"] == 8 and default["seeds_independent"] == 6
    assert default["spread_paired"] == pytest.approx(paired.std(ddof=1))
    assert default["narrower_by"] == pytest.approx(
        single.std(ddof=1) / paired.std(ddof=1)
    )
    assert default["caution_paired"] == 1
    assert (
        default["rollouts_paired"] == 2000 and default["rollouts_independent"] == 2100
    )
    halves = np.append(indep, 3e-5)
    assert at_half["seeds_independent"] == 9
    assert at_half["narrower_by"] == pytest.approx(
        halves.std(ddof=1) / even_diff.std(ddof=1)
    )
    assert at_half["rollouts_paired"] == 1900 == at_half["rollouts_independent"]
    assert "| default paired / two default single runs | 8 / 6 |" in md
    assert "| even paired / two runs at half the default | 5 / 9 |" in md


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
        bench, "independent_record", lambda seed, scratch, *_: {"seconds": 0.0}
    )
    bench.run([2, 1, 0], path)
    assert ran == [2, 0]
    assert sorted(bench._done(path)) == [0, 1, 2]
