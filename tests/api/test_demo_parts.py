"""The demo through the API: the exact problems' estimates, then the scenario's runs."""

import json

import pytest

import avrisk.api.runs as api_runs
from avrisk.api import UserError, events
from avrisk.api.demo import ExactEstimates, run_demo


def test_the_exact_problems_are_estimated_at_the_budget_and_reported_in_order(
    tmp_path,
):
    seen = []
    out = tmp_path / "demo.json"
    result = run_demo(budget=50_000, seed=3, out=out, rollouts=0, progress=seen.append)
    assert result.scenario is None
    exact = result.exact
    assert (exact.budget, exact.seed, exact.written) == (50_000, 3, out)
    assert seen[-1] == exact  # handed over once the part is done
    written = json.loads(out.read_text())
    assert list(written) == [problem.name for problem, _ in exact.problems]
    for problem, (naive, ce) in exact.problems:
        assert (naive.method, ce.method) == ("naive_mc", "cross_entropy")
        assert naive.n_evals == ce.n_evals == 50_000
        assert abs(ce.p - problem.p_exact) < 5 * ce.stderr
        assert written[problem.name] == {
            "p_exact": problem.p_exact,
            "naive_mc": json.loads(json.dumps(naive.to_dict())),
            "cross_entropy": json.loads(json.dumps(ce.to_dict())),
        }
        label = f"CE {problem.name}"
        runs = [e for e in seen[:-1] if e.label == label]
        assert runs[0] == events.RunOpened(label, None)
        assert runs[-1] == events.RunClosed(label, None)
        (started,) = [e for e in runs if isinstance(e, events.RunStarted)]
        assert started.total == 50_000
        advanced = sum(e.n for e in runs if isinstance(e, events.Advanced))
        assert advanced == 50_000


def test_a_budget_below_the_minimum_or_too_few_rollouts_is_refused_first():
    seen = []
    with pytest.raises(UserError, match="at least 50,000"):
        run_demo(budget=10_000, progress=seen.append)
    with pytest.raises(UserError, match="n_particles"):
        run_demo(budget=50_000, rollouts=5, progress=seen.append)
    assert seen == []


def test_the_scenario_part_compares_splitting_is_after_the_exact_part(
    tmp_path, monkeypatch
):
    seen, asked = [], []

    def compare_runs(scenario, out, settings, **kwargs):
        asked.append((scenario, out, settings, kwargs, list(seen)))
        return "the comparison"

    monkeypatch.setattr(api_runs, "compare_runs", compare_runs)
    result = run_demo(
        budget=50_000,
        rollouts=2000,
        reference=300,
        seed=1,
        scenario_out=tmp_path / "runs",
        progress=seen.append,
    )
    assert result.scenario == "the comparison"
    ((scenario, out, settings, kwargs, before),) = asked
    assert (scenario, out) == ("highway_default", tmp_path / "runs")
    assert isinstance(before[-1], ExactEstimates) and before[-1].written is None
    assert settings.method == "splitting_is" and settings.seed == 1
    assert settings.gamma == 0.1 and settings.gamma_test == (0.2, 0.3, 0.5, 1.0)
    options = settings.to_dict()
    assert (options["n_particles"], options["n_final"]) == (200, 1000)
    assert settings.batch_size == 1024
    assert kwargs["reference_n"] == 300 and kwargs["progress"] == seen.append
