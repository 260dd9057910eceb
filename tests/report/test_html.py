import hashlib
import json
import re

import pytest
from markupsafe import escape as html_escape

from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare.splitting_importance import SplittingImportanceSampling
from avrisk.report.html import top_failures, write_report
from avrisk.report.plots import comparison_rows, table_cells
from avrisk.testing import beta_sum_problem

PROBLEM = beta_sum_problem(6, p=1e-5)
NAMES = [f"veh{i}.s" for i in range(6)]
GAMMAS = (PROBLEM.gamma - 3.0, PROBLEM.gamma + 3.0)


def f(x):
    return {"f": PROBLEM.f(x), "crash": PROBLEM.f(x) < PROBLEM.gamma - 5.0}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    ce = RunSettings(
        method="ce",
        gamma=PROBLEM.gamma,
        gamma_test=GAMMAS,
        rho=0.1,
        n_per_iter=2000,
        n_iter=6,
        n_final=10_000,
    )
    naive = RunSettings(
        method="naive", gamma=PROBLEM.gamma, gamma_test=GAMMAS, n_final=22_000
    )
    out = []
    for label, settings in (("CE", ce), ("naive", naive)):
        run_dir = RunDirectory(root / settings.method, NAMES)
        run_estimation(run_dir, PROBLEM.base, f, settings)
        out.append((label, run_dir))
    return root, out


def test_report_has_every_section_and_only_working_image_links(runs):
    root, dirs = runs
    calls = []

    def animate(row, path):
        calls.append(row)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"GIF89a")
        return path

    report = write_report(
        root / "report",
        dirs,
        title="t",
        failures_from=dirs[0][1],
        n_failures=3,
        param_names=NAMES,
        animate=animate,
    )
    html = report.read_text()
    for heading in (
        "CE vs naive Monte Carlo",
        "Most likely failures under P0",
        "Settings",
    ):
        assert heading in html
    assert "&amp;ndash;" not in html
    links = re.findall(r'src="([^"]+)"', html)
    assert "plots/comparison.png" in links and "animations/failure_1.gif" in links
    for link in links:
        assert (root / "report" / link).is_file(), link
    assert len(calls) == 3


def test_failures_are_ranked_by_their_likelihood_under_p0(runs):
    _, dirs = runs
    rows = top_failures(dirs[0][1], PROBLEM.gamma, 10)
    assert len(rows) == 10
    log_p0 = [r["log_p0"] for r in rows]
    assert log_p0 == sorted(log_p0, reverse=True)
    assert all(r["f"] <= PROBLEM.gamma for r in rows)
    table = dirs[0][1].samples(["f", "log_p0"])
    hit = table["f"].to_numpy() <= PROBLEM.gamma
    assert log_p0[0] == table["log_p0"].to_numpy()[hit].max()


def test_comparison_ratios_are_against_naive_mc_with_ces_whole_budget(runs):
    _, dirs = runs
    ce = dirs[0][1].summary()["estimate"]
    n = ce["n_evals"]  # search iterations and final stage together
    assert n > ce["by_gamma"][0]["n_samples"]
    rows = comparison_rows(ce)
    for row, g in zip(
        rows, sorted(ce["by_gamma"], key=lambda g: g["gamma"]), strict=True
    ):
        assert row["naive_hits_expected"] == pytest.approx(n * g["p"])
        assert row["rare_event_ratio"] == pytest.approx(g["n_hits"] / (n * g["p"]))
        # variance_reduction compares with naive MC of the final stage's size.
        assert row["variance_ratio"] == pytest.approx(
            g["variance_reduction"] * g["n_samples"] / n
        )
        assert row["rare_event_ratio"] > 5 and row["variance_ratio"] > 5
        assert row["reliable"] == (g["ess"] >= 10 and g["pareto_k"] <= 0.7)


def _reseal(path, text):
    """Write a made-up summary and its digest (as a run would have recorded it)."""
    path.write_text(text)
    manifest = path.parent / "manifest.json"
    record = json.loads(manifest.read_text())
    record["summary"]["sha256"] = hashlib.sha256(text.encode()).hexdigest()
    manifest.write_text(json.dumps(record))


def test_a_variance_ratio_from_few_effective_hits_is_marked_unreliable(runs, tmp_path):
    root, dirs = runs
    ce = dirs[0][1].summary()["estimate"]
    shaky = {**ce, "by_gamma": [{**g, "ess": 1.4} for g in ce["by_gamma"]]}
    assert not any(row["reliable"] for row in comparison_rows(shaky))
    heavy = {**ce, "by_gamma": [{**g, "pareto_k": 0.9} for g in ce["by_gamma"]]}
    assert not any(row["reliable"] for row in comparison_rows(heavy))
    unknown = {**ce, "by_gamma": [{**g, "pareto_k": None} for g in ce["by_gamma"]]}
    assert all(row["reliable"] for row in comparison_rows(unknown))
    assert all(row["reliable"] for row in comparison_rows(ce))

    report = write_report(tmp_path / "report", dirs, title="t")
    assert "effective hits of the method" not in report.read_text()
    summary_path = dirs[0][1].path / "summary.json"
    original = summary_path.read_text()
    try:
        summary = json.loads(original)
        summary["estimate"]["by_gamma"][0]["ess"] = 1.4
        _reseal(summary_path, json.dumps(summary))
        text = write_report(tmp_path / "shaky", dirs, title="t").read_text()
    finally:
        _reseal(summary_path, original)
    assert (
        "fewer than 10 effective hits of the method, or hit weights with a heavy tail"
        in text
    )
    assert text.count("</td></tr>") > 0 and "*</td></tr>" in text


def test_naive_runs_are_never_marked_unreliable(runs, tmp_path):
    root, dirs = runs
    summary_path = dirs[1][1].path / "summary.json"
    original = summary_path.read_text()
    try:
        summary = json.loads(original)
        assert summary["estimate"]["method"] == "naive_mc"
        for g in summary["estimate"]["by_gamma"]:
            g.update(n_hits=2, ess=2.0)
        _reseal(summary_path, json.dumps(summary))
        text = write_report(tmp_path / "naive", dirs[1:], title="t").read_text()
    finally:
        _reseal(summary_path, original)
    assert "*</td></tr>" not in text


def test_a_naive_run_with_few_hits_is_told_its_relative_error(runs, tmp_path):
    root, dirs = runs
    summary_path = dirs[1][1].path / "summary.json"
    original = summary_path.read_text()
    try:
        summary = json.loads(original)
        for g in summary["estimate"]["by_gamma"]:
            g.update(n_hits=4, ess=4.0)
        _reseal(summary_path, json.dumps(summary))
        text = write_report(tmp_path / "few", dirs[1:], title="t").read_text()
    finally:
        _reseal(summary_path, original)
    assert "only 4 hits: relative standard error about 50%" in text
    assert "weights dominate" not in text


def test_the_report_leads_with_one_answer_and_its_trust(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "r", dirs, title="t").read_text()
    answer = text.index('id="answer"')
    assert answer < text.index("<h2>")  # before any other section
    block = text[answer : text.index("</div>", answer)]
    assert "P(min TTC ≤" in block and "per rollout from P0" in block
    assert "95% CI" in block and "method " in block and "trust:" in block
    assert "Of the 2 runs below" in block


def test_one_variance_ratio_per_threshold_and_no_borrowed_reference(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "single", dirs[:1], title="t").read_text()
    # one variance ratio: against naive MC with the run's whole budget
    assert "variance reduction" not in text and "final-stage n" not in text
    assert text.count("variance ratio: naive MC at") == 1
    ce = dirs[0][1].summary()["estimate"]
    for row in comparison_rows(ce):
        assert f"{row['variance_ratio']:.3g}" in text
    # a single run has no reference: its own estimate is named so
    assert "p (reference)" not in text and "reference run" not in text.split("<h2>")[0]
    assert "this run&#39;s own estimate" in text
    with_ref = write_report(
        tmp_path / "ref", dirs, title="t", reference=dirs[1][1]
    ).read_text()
    assert "naive reference" in with_ref and "there is no reference" not in with_ref


def test_every_threshold_dependent_column_names_its_threshold(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "r", dirs, title="t").read_text()
    headers = re.findall(r"<th[^>]*>([^<]*)</th>", text)
    for header in headers:
        if header.startswith(("P(", "hits", "p used", "naive hits", "what happened")):
            assert "gamma" in header or " s)" in header, header


def test_splitting_is_shows_its_levels_proposal_and_cross_check(tmp_path):
    settings = RunSettings(
        method="splitting_is",
        gamma=PROBLEM.gamma,
        gamma_test=GAMMAS,
        n_particles=500,
        n_final=2000,
    )
    run_dir = RunDirectory(tmp_path / "splitting_is", NAMES)
    run_estimation(run_dir, PROBLEM.base, f, settings)
    html = write_report(tmp_path / "report", [("splitting + IS", run_dir)], title="t")
    text = html.read_text()
    tables = SplittingImportanceSampling.diagnostics(run_dir.summary()["estimate"])
    drawn = [t for t in tables if t.drawn]
    assert [t.title for t in drawn] == ["Subset simulation levels"]
    assert (tmp_path / "report" / "plots" / "diagnostics_0_0.png").is_file()
    for table in (t for t in tables if not t.drawn):
        title = f"<h3>{html_escape(table.title)}</h3>"
        section = text.split(title, 1)[1].split("</table>")[0]
        assert re.findall(r"<th>([^<]*)</th>", section) == [
            html_escape(c) for c in table.columns
        ]
        cells = re.findall(r"<td>([^<]*)</td>", section)
        assert cells == [c for row in table_cells(table) for c in row]
    assert len(re.findall(r"<h3>", text)) == 2  # the proposal and the cross-check
