import hashlib
import json
import re

import pytest
from markupsafe import escape as html_escape

from avrisk.assembly import base_distribution, param_layout
from avrisk.pipeline import RunDirectory, RunSettings, run_estimation
from avrisk.rare.splitting_importance import SplittingImportanceSampling
from avrisk.report.html import SECTIONS, top_failures, write_report
from avrisk.report.plots import comparison_rows, table_cells
from avrisk.scenario import load_spec
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
        "Most likely failures (min TTC",
        "Settings",
    ):
        assert heading in html
    assert "&amp;ndash;" not in html
    links = re.findall(r'src="([^"]+)"', html)
    assert "plots/comparison.png" in links and "animations/failure_1.gif" in links
    for link in links:
        assert (root / "report" / link).is_file(), link
    assert len(calls) == 3


def test_a_black_boxs_failures_are_ranked_by_their_likelihood_under_p0(runs):
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
    block = text[answer : text.index("</section>", answer)]
    assert "P(min TTC ≤" in block and "per rollout from P0" in block
    assert "95% CI" in block and "method " in block and "trust:" in block
    assert "Of the 2 runs compared below" in block
    assert "P0 is the distribution the inputs of a rollout are" in block


def test_one_variance_ratio_per_threshold_and_no_borrowed_reference(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "single", dirs[:1], title="t").read_text()
    # one variance ratio: against naive MC with the run's whole budget
    assert "variance reduction" not in text and "final-stage n" not in text
    assert text.count("<th>variance ratio</th>") == 1
    ce = dirs[0][1].summary()["estimate"]
    for row in comparison_rows(ce):
        assert f"{row['variance_ratio']:.3g}" in text
    # a single run has no reference: its own estimate is named so
    assert "p (reference)" not in text and "reference run" not in text.split("<h2>")[0]
    assert "this run's own estimate" in text
    with_ref = write_report(
        tmp_path / "ref", dirs, title="t", reference=dirs[1][1]
    ).read_text()
    assert "naive reference" in with_ref and "there is no reference" not in with_ref


def test_headers_are_short_and_each_is_explained_in_a_legend(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "r", dirs, title="t").read_text()
    headers = set(re.findall(r"<th[^>]*>([^<]*)</th>", text))
    # a column's meaning, threshold and units go to the legend below it
    long = [h for h in headers if len(h) > 20]
    assert not long, long
    legends = re.findall(r"<dt>([^<]*)</dt>", text)
    for header in ("p", "hits", "ESS", "Pareto k", "trust", "p used", "naive hits"):
        assert header in headers and header in legends, header
    assert "variance ratio" in legends and "rare-event ratio" in legends


def test_the_answer_and_the_failures_come_before_the_estimators_statistics(
    runs, tmp_path
):
    _, dirs = runs
    text = write_report(
        tmp_path / "r", dirs, title="t", failures_from=dirs[0][1], n_failures=3
    ).read_text()
    starts = [text.index(f'id="{name}"') for name in SECTIONS]
    assert starts == sorted(starts)
    last_card = text.rindex('<div class="failure">')
    for statistic in ("<th>ESS</th>", "<th>Pareto k</th>", 'src="plots/'):
        assert last_card < text.index(statistic), statistic
    # each failure names the step that drew it as the diagnostics do
    steps = re.findall(r"from\s+([^,]+), sample", text)
    assert len(steps) == 3 and set(steps) <= {
        "the final stage",
        *(f"CE iteration {k}" for k in range(6)),
    }


def test_a_multi_run_report_shows_each_runs_settings(runs, tmp_path):
    _, dirs = runs
    text = write_report(tmp_path / "r", dirs, title="t").read_text()
    table = text[text.index('id="settings"') :].split("</table>")[0]
    rows = {
        cells[0]: cells[1:]
        for cells in (
            re.findall(r"<t[dh][^>]*>([^<]*)</t[dh]>", row)
            for row in table.split("<tr>")[1:]
        )
    }
    assert rows["setting"] == ["CE", "naive"]
    assert rows["method"] == ["ce", "naive"]
    assert rows["n_final"] == ["10,000", "22,000"]
    assert rows["rho"] == ["0.1", "-"]  # a CE setting naive MC does not have


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
    html = write_report(
        tmp_path / "report",
        [("splitting + IS", run_dir)],
        title="t",
        failures_from=run_dir,
        n_failures=40,
    )
    text = html.read_text()
    estimate = run_dir.summary()["estimate"]
    tables = SplittingImportanceSampling.diagnostics(estimate)
    drawn = [t for t in tables if t.drawn]
    assert [t.title for t in drawn] == [
        "Subset simulation levels, replicate 1",
        "Subset simulation levels, replicate 2",
    ]
    for j in range(2):
        assert (tmp_path / "report" / "plots" / f"diagnostics_0_{j}.png").is_file()
    assert text.count(html_escape(drawn[0].note)) == 1  # said once for both
    for table in (t for t in tables if not t.drawn):
        title = f"<h4>{html_escape(table.title)}</h4>"
        section = text.split(title, 1)[1].split("</table>")[0]
        assert re.findall(r"<th>([^<]*)</th>", section) == [
            html_escape(c) for c in table.columns
        ]
        cells = re.findall(r"<td>([^<]*)</td>", section)
        assert cells == [c for row in table_cells(table) for c in row]
        assert html_escape(table.note) in text
    # a failure's step is named as the levels' plots name their sets
    steps = set(re.findall(r"from\s+([^,]+(?:, set \d+)?), sample", text))
    sets = {f"replicate {r}, set {k}" for r in (1, 2) for k in range(12)}
    assert steps <= sets | {"the moves at gamma", "the importance-sampling stage"}
    assert steps & sets  # the levels' own hits are among the failures


@pytest.fixture(scope="module")
def replicated(tmp_path_factory):
    settings = RunSettings(
        method="splitting_is", gamma=PROBLEM.gamma, n_particles=500, n_final=1000
    )
    run_dir = RunDirectory(tmp_path_factory.mktemp("replicated"), NAMES)
    run_estimation(run_dir, PROBLEM.base, f, settings)
    return run_dir


def test_the_samples_of_splitting_is_are_named_by_the_step_that_drew_them(
    replicated,
):
    estimate = replicated.summary()["estimate"]
    stages = replicated.samples(["stage"])["stage"].to_numpy()
    label = SplittingImportanceSampling.stage_label
    names = [label(estimate, int(s)) for s in stages]
    first = [h for h in estimate["history"] if h["replicate"] == 0]
    assert names.count("replicate 1, set 0") == 250  # N / 2 draws of P0
    calls = 0
    for h in first:  # each set's own calls of f
        assert names.count(f"replicate 1, set {h['index']}") == h["n_evals"] - calls
        calls = h["n_evals"]
    assert names.count("the importance-sampling stage") == 1000
    assert "the moves at gamma" in names
    assert any(n.startswith("replicate 2, set ") for n in names)


def test_no_two_steps_of_splitting_is_share_a_stage(replicated):
    estimate = replicated.summary()["estimate"]
    assert replicated.samples(["stage"]).num_rows == estimate["n_evals"]


def test_a_scenarios_failures_read_as_two_percentiles_most_realistic_first(tmp_path):
    spec = load_spec("highway_default")  # learned drivers: xi in X
    base, columns = base_distribution(spec), param_layout(spec).columns
    ego_speed = columns.index("veh0.speed")

    def fast_ego(x):  # dangerous: the ego starts faster than about 18 m/s
        return {"f": 20.0 - x[:, ego_speed]}

    run_dir = RunDirectory(tmp_path / "run", columns)
    settings = RunSettings(method="naive", gamma=2.0, n_final=1500)
    run_estimation(run_dir, base, fast_ego, settings)
    text = write_report(
        tmp_path / "report",
        [("naive", run_dir)],
        title="t",
        failures_from=run_dir,
        n_failures=5,
        param_names=columns,
        spec=spec,
    ).read_text()
    cards = re.findall(r"start <b>([^<]+)</b>\s*&middot; drivers <b>([^<]+)</b>", text)
    assert len(cards) == 5
    shares = [[0.0 if v == "&lt; 0.01" else float(v) for v in c] for c in cards]
    assert all(0.0 <= v <= 100.0 for card in shares for v in card)
    lowest = [min(card) for card in shares]
    assert lowest == sorted(lowest, reverse=True)  # ranked by the lower one
    assert text.count("from\n      the draws of P0") == 5
    intro = text[text.index('id="failures"') : text.index('<div class="failure">')]
    assert "<b>start</b>: the percentile of the initial situation" in intro
    assert "<b>drivers</b>: the same for the learned drivers" in intro
