"""The exact suite's problems against independent Monte Carlo, and its command.

Each problem's ``p_exact`` is computed without calling its ``f`` (closed form,
quadrature, conditional Monte Carlo); here ``f`` itself is sampled, naively or
by importance sampling from a wider normal (weights at most ``s^D``), so a
wrong formula, parameter or transform in either fails. The generated families
are checked at parameters where naive sampling sees the event (the same code
builds their rare points).
"""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from avrisk.testing.generated import (
    PLATEAU_CAP,
    beta_pair_product_problem,
    beta_product_problem,
    decoy_problem,
    directions,
    k_region_problem,
    plateau_problem,
)
from avrisk.testing.limit_states import CONDITIONAL_MC
from avrisk.testing.reliability import RELIABILITY_PROBLEMS, conditional_mc_reference
from avrisk.testing.suite import SUITE, suite_problem

ROOT = Path(__file__).resolve().parents[2]


def _naive(problem, n, rng, chunk=200_000):
    hits = 0
    for start in range(0, n, chunk):
        x = problem.base.sample(min(chunk, n - start), rng)
        hits += int(np.count_nonzero(problem.f(x) <= problem.gamma))
    p = hits / n
    return p, np.sqrt(max(p * (1 - p), 1e-300) / n)


def _wide(problem, n, rng, scale):
    """IS from ``N(0, scale^2 I)`` in the base's standard-normal space."""
    d = problem.base.dim
    z = rng.standard_normal((n, d)) * scale
    log_w = d * np.log(scale) - 0.5 * (z * z).sum(axis=1) * (1 - 1 / scale**2)
    hit = problem.f(problem.base.from_standard_normal(z)) <= problem.gamma
    w = np.where(hit, np.exp(log_w), 0.0)
    return w.mean(), w.std() / np.sqrt(n)


def _agrees(estimate, stderr, problem, k=4.5):
    ref_se = problem.p_exact * problem.p_rel_error
    return abs(estimate - problem.p_exact) <= k * np.hypot(stderr, ref_se)


# Reliability problems: naive where p is not too small, else a wider normal.
WIDE_SCALE = {2: 2.0, 3: 1.8, 5: 1.5, 6: 1.4, 7: 1.35, 10: 1.3}


@pytest.mark.parametrize("name", [*RELIABILITY_PROBLEMS, "four-branch"])
def test_reliability_reference_agrees_with_sampling_its_f(name):
    problem = suite_problem(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    d = problem.base.dim
    if problem.p_exact > 3e-4 or d not in WIDE_SCALE:
        estimate, stderr = _naive(problem, 1_000_000, rng)
    else:
        estimate, stderr = _wide(problem, 1_000_000, rng, WIDE_SCALE[d])
    assert stderr < 0.15 * problem.p_exact, "the check is too weak to fail"
    assert _agrees(estimate, stderr, problem), (estimate, stderr, problem.p_exact)


@pytest.mark.parametrize("name", sorted(CONDITIONAL_MC))
def test_stored_conditional_reference_is_reproduced_with_another_seed(name):
    problem = suite_problem(name)
    p, rel = conditional_mc_reference(name, 400_000, seed=7)
    assert abs(p / problem.p_exact - 1) < 5 * np.hypot(rel, problem.p_rel_error)


def test_listed_values_that_are_right_are_reproduced():
    # otbenchmark's values that agree with closed forms (RP22, RP25, RP75 are
    # quoted there to 10+ digits); catches a wrong quadrature set-up
    assert suite_problem("RP22").p_exact == pytest.approx(4.20730551129961794e-3, 1e-8)
    assert suite_problem("RP25").p_exact == pytest.approx(4.148566293759747e-05, 1e-7)
    assert suite_problem("RP75").p_exact == pytest.approx(9.81929872154689e-3, 1e-8)
    assert suite_problem("RP107").p_exact == pytest.approx(stats.norm.sf(5.0))


@pytest.mark.parametrize("k, dim, ratio", [(1, 2, 0.5), (3, 5, 0.5), (4, 30, 0.2)])
def test_k_regions_exact_p_agrees_with_naive_sampling(k, dim, ratio):
    problem = k_region_problem(k, dim, p=2e-2, ratio=ratio)
    assert problem.p_exact == pytest.approx(2e-2, rel=1e-10)
    estimate, stderr = _naive(problem, 400_000, np.random.default_rng(k))
    assert _agrees(estimate, stderr, problem)


def test_k_regions_have_unequal_masses_and_orthogonal_normals():
    problem = k_region_problem(5, 50, p=1e-6)
    betas = [float(b) for b in problem.reference.split("beta = ")[1].split(", ")]
    masses = stats.norm.sf(betas)
    assert np.allclose(masses[1:] / masses[:-1], 0.5, rtol=1e-2)  # betas rounded
    normals = directions(50, 5)
    assert np.allclose(normals @ normals.T, np.eye(5), atol=1e-12)
    # on each region's own normal f crosses 0 at that region's beta
    for beta, a in zip(betas, normals, strict=True):
        assert problem.f(np.array([0.999 * beta * a]))[0] > 0
        assert problem.f(np.array([1.001 * beta * a]))[0] < 0


@pytest.mark.parametrize("kind", ["self", "gate"])
def test_plateau_exact_p_and_plateau_mass_agree_with_naive_sampling(kind):
    problem = plateau_problem(0.9, p=1e-2, dim=10, kind=kind)
    rng = np.random.default_rng(3)
    x = problem.base.sample(400_000, rng)
    values = problem.f(x)
    hits = np.count_nonzero(values <= problem.gamma) / len(x)
    assert _agrees(hits, np.sqrt(hits * (1 - hits) / len(x)), problem)
    tie = values == values.max()
    share = float(problem.reference.split(" on ")[1].split(" of")[0])
    assert abs(tie.mean() - share) < 5 * np.sqrt(share * (1 - share) / len(x))
    assert values.max() == pytest.approx(
        PLATEAU_CAP if kind == "gate" else values.max()
    )


def test_plateau_holds_the_stated_share_at_the_suites_points():
    for share in (0.9, 0.99, 0.9999):
        problem = plateau_problem(share, p=1e-6, dim=10)
        x = problem.base.sample(200_000, np.random.default_rng(5))
        values = problem.f(x)
        tie = values == values.max()
        assert abs(tie.mean() - share) < 5 * np.sqrt(share * (1 - share) / 2e5) + 1e-5


def test_decoy_exact_p_share_and_floor_agree_with_naive_sampling():
    problem = decoy_problem(0.3, p=1e-3, dim=4)
    x = problem.base.sample(1_000_000, np.random.default_rng(11))
    values = problem.f(x)
    hits = np.count_nonzero(values <= problem.gamma) / len(x)
    assert _agrees(hits, np.sqrt(hits * (1 - hits) / len(x)), problem)
    # the true mechanism holds 30% of P0(f <= 1); the decoy none of f <= 0.5
    a = directions(4, 2)[0]
    below_one = values <= 1.0
    true_share = np.mean(1.33 * (stats.norm.isf(1e-3) - x[below_one] @ a) <= 1.0)
    assert abs(true_share - 0.3) < 5 * np.sqrt(0.3 * 0.7 / below_one.sum())
    assert np.all((values > 0.5) | (x @ a >= stats.norm.isf(1e-3) - 0.5 / 1.33))


@pytest.mark.parametrize(
    "problem",
    [beta_product_problem(3, p=1e-2), beta_pair_product_problem(p=1e-2)],
    ids=["product", "pair"],
)
def test_beta_products_agree_with_naive_sampling(problem):
    assert problem.p_exact == pytest.approx(1e-2, rel=1e-9)
    estimate, stderr = _naive(problem, 400_000, np.random.default_rng(9))
    assert _agrees(estimate, stderr, problem)


def test_every_suite_name_builds_and_is_rare():
    for name in SUITE:
        problem = suite_problem(name)
        assert 1e-10 < problem.p_exact < 0.05, name
        assert problem.reference
    with pytest.raises(KeyError, match="kregions"):
        suite_problem("RP999")


def _load_suite_command():
    spec = importlib.util.spec_from_file_location(
        "exact_suite", ROOT / "benchmarks" / "exact_suite.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_suite_command_runs_resumes_and_tabulates(tmp_path, capsys):
    suite = _load_suite_command()
    out = tmp_path / "runs.jsonl"
    methods = ["splitting_is", "ce"]
    if importlib.util.find_spec("openturns") is not None:  # the bench extra
        methods.append("ot_ce")
    args = [
        "run",
        "--problems",
        "RP22,plateau_self_m0.9999_d10_p1e-06",
        "--methods",
        ",".join(methods),
        "--seeds",
        "0",
        "--out",
        str(out),
    ]
    suite.main(args)
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(records) == 2 * len(methods)
    assert {r["method"] for r in records} == set(methods)
    for r in records:
        assert r["error"] is not None or r["n_calls"] <= suite.SUITE_BUDGET
    rp22 = [r for r in records if r["problem"] == "RP22" and r["method"] != "ot_ce"]
    assert all(r["error"] is None and r["trust"] in ("ok", "caution") for r in rp22)
    suite.main(args)  # resumed: nothing new
    assert len(out.read_text().splitlines()) == 2 * len(methods)
    md, js = tmp_path / "t.md", tmp_path / "t.json"
    suite.main(["table", "--results", str(out), "--md", str(md), "--json", str(js)])
    rows = json.loads(js.read_text())
    assert {(r["problem"], r["method"]) for r in rows} >= {("RP22", "splitting_is")}
    assert "| RP22 |" in md.read_text()
    # a method's runs from the first file that names it, the rest from the next
    suite.main(["table", "--results", f"{out}:ce", "--json", str(js)])
    assert {r["method"] for r in json.loads(js.read_text())} == {"ce"}
    suite.main(["table", "--results", f"{out}:ce", str(out), "--json", str(js)])
    assert {r["method"] for r in json.loads(js.read_text())} == set(methods)


def test_suite_settings_keep_every_engine_method_within_the_budget():
    from avrisk.rare.estimator import get_estimator

    suite = _load_suite_command()
    for method in ("splitting_is", "splitting", "mixture", "ce", "naive"):
        settings = suite.suite_settings(method)
        budget = get_estimator(method, **settings).budget()
        assert 0.9 * suite.SUITE_BUDGET <= budget <= suite.SUITE_BUDGET, method


def test_a_variant_is_scaled_to_the_same_budget():
    from avrisk.rare.estimator import get_estimator, planned_budget

    suite = _load_suite_command()
    default = suite.suite_settings("splitting_is")
    variant = suite.suite_settings("splitting_is", {"n_moves": 3})
    assert variant["n_moves"] == 3 and variant["n_particles"] < default["n_particles"]
    estimator = get_estimator("splitting_is", **variant)
    assert planned_budget(estimator) <= suite.SUITE_BUDGET


def test_gross_miss_needs_both_a_missed_interval_and_a_factor_two():
    suite = _load_suite_command()
    run = {"p_exact": 1.0, "p_rel_error": 0.0}
    assert suite._gross({**run, "p": 0.4, "ci": [0.3, 0.5]})
    assert not suite._gross({**run, "p": 0.6, "ci": [0.5, 0.7]})  # within 2x
    assert not suite._gross({**run, "p": 0.4, "ci": [0.1, 1.2]})  # covers


def test_a_variant_on_top_keeps_the_default_s_counts_and_adds_its_own_calls():
    from avrisk.rare.estimator import get_estimator, planned_budget

    suite = _load_suite_command()
    default = suite.suite_settings("splitting_is")
    variant = suite.suite_settings("splitting_is", {"refresh_rounds": 4}, on_top=True)
    assert {k: variant[k] for k in ("n_particles", "n_final")} == {
        k: default[k] for k in ("n_particles", "n_final")
    }
    uncapped = {k: v for k, v in default.items() if k != "max_calls"}
    added = planned_budget(
        get_estimator("splitting_is", **uncapped, refresh_rounds=4)
    ) - planned_budget(get_estimator("splitting_is", **uncapped))
    assert added == 2 * default["n_particles"]  # one call a particle a round
    assert variant["max_calls"] == default["max_calls"] + added
    get_estimator("splitting_is", **variant)  # its bound within its cap
    # a method without a cap of calls takes the change alone
    ce = suite.suite_settings("ce", {"rho": 0.2}, on_top=True)
    assert ce == {**suite.suite_settings("ce"), "rho": 0.2}
