"""What a person and a script see: 80 columns, ``--json``, the cost, Ctrl-C."""

import inspect
import io
import json
import shlex
import subprocess
import sys

import pytest
from rich.console import Console
from typer.testing import CliRunner

from avrisk.cli.app import COMMANDS, app, docstring
from avrisk.cli.demo import analytic_table
from avrisk.cli.estimator_options import estimator_options
from avrisk.cli.run import COMPARE_DEFAULTS, compare
from avrisk.rare import cross_entropy, get_estimator, naive_mc
from avrisk.rare.proposal_audit import audit_bound
from avrisk.testing import beta_sum_problem, gaussian_linear_problem
from tests.interrupts import ctrl_c_at_chunk
from tests.scenario_files import shortened_scenario


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory):
    """``highway_idm`` cut to 1.5 s, to keep the tests fast."""
    return shortened_scenario(tmp_path_factory.mktemp("scenario"), 1.5)


RUN_ARGS = ("--method", "ce", "--rho", "0.1", "--n-per-iter", "60", "--n-iter", "2")
RUN_ARGS += ("--n-final", "100")
RUN_ARGS += ("--gamma", "1.0", "--gamma-test", "0.5,2.0", "--batch-size", "64")
RUN_ARGS += ("--failures", "1")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "80"})


def words(text):
    """``text`` with every run of white space (wrapped lines) as one space."""
    return " ".join(text.split())


def assert_whole_at_80_columns(text):
    """No line of ``text`` wider than 80 columns, no cell cut with an ellipsis."""
    for line in text.splitlines():
        assert len(line) <= 80, line
    assert "…" not in text


@pytest.mark.filterwarnings("ignore::avrisk.rare.final_stage.UnreliableEstimateWarning")
def test_the_demo_table_is_whole_at_80_columns():
    rows = []
    for problem in (beta_sum_problem(6, p=1e-5), gaussian_linear_problem(100, p=1e-6)):
        naive = naive_mc(problem.f, problem.base, problem.gamma, 2000, seed=0)
        ce = cross_entropy(
            problem.f, problem.base, problem.gamma, rho=0.1, n_per_iter=500,
            n_iter=3, n_final=1000, seed=0,
        )  # fmt: skip
        rows.append((problem, [naive, ce]))
    console = Console(width=80, record=True, file=io.StringIO())
    console.print(analytic_table(2000, 0, rows))
    text = console.export_text()
    assert_whole_at_80_columns(text)
    for problem, estimates in rows:
        assert problem.name in text and f"{problem.p_exact:.3e}" in text
        for est in estimates:  # every cell whole, on one line
            lo, hi = est.ci
            assert f"{est.p:.3e}" in text and f"{lo:.2e}..{hi:.2e}" in text


def test_run_fits_80_columns_and_leads_with_the_answer(short_scenario, tmp_path):
    result = invoke("run", short_scenario, "--out", tmp_path / "run", *RUN_ARGS)
    assert result.exit_code == 0, result.output
    assert_whole_at_80_columns(result.stdout)
    for line in result.stderr.splitlines():  # but the path of the report
        assert len(line) <= 80 or line.startswith("report: "), line
    first = result.stdout.lstrip().splitlines()[0]
    assert first.startswith("P(min TTC <= 1 s) per 1.5-s rollout from P0 = ")
    assert "trust:" in result.stdout and "Per hour of" in result.stdout
    # every column of the table is there, none cut short
    for header in ("gamma [s]", "stderr", "95% CI", "hits", "ESS", "Pareto k"):
        assert header in result.stdout


def test_a_search_that_converged_says_so(short_scenario, tmp_path):
    out = tmp_path / "run"
    args = [a if a != "1.0" else "1.5" for a in RUN_ARGS]  # --gamma 1.5: in reach
    result = invoke("run", short_scenario, "--out", out, *args)
    assert result.exit_code == 0, result.output
    doc = json.loads(invoke("report", out, "--failures", 0, "--json").stdout)
    search = doc["runs"][0]["search"]
    assert search["converged"] and search["n_iter"] == 2
    assert search["gamma"] == 1.5 and search["last_quantile"] <= 1.5
    assert f"cross-entropy: {search['sentence']}" in words(result.stdout)
    assert search["sentence"].endswith("and held it (converged)")
    assert not any("search" in r for r in doc["answer"]["reasons"])


def test_the_plan_and_the_measured_rate_come_before_the_results(
    short_scenario, tmp_path
):
    result = invoke("run", short_scenario, "--out", tmp_path / "run", *RUN_ARGS)
    err = words(result.stderr)
    # CE's 220 and at most 12 sets of its audit's 20 particles
    assert (
        "plan: cross-entropy (CE 2x60 + 100, audit 20): at most 460 rollouts "
        "(fewer if the levels reach gamma sooner); samples take" in err
    )
    # 24 parameters of highway_idm: 24 x 9.5 + 45 B
    assert "at most about 126 kB on disk (an estimate: 273 B a rollout)" in err
    assert "rate: " in err and "rollouts/s on the first 60: at most about" in err
    assert err.index("plan:") < err.index("rate:")
    assert disk_figures(err)[0] == pytest.approx(273, rel=0.15)  # as estimated


def test_the_default_method_is_splitting_is_its_plan_a_bound_and_its_tables_shown(
    short_scenario, tmp_path
):
    out = tmp_path / "run"
    args = ("--set", "n_particles=100", "--n-final", 100, "--gamma", 1.0)
    args += ("--gamma-test", "2.0", "--batch-size", 64, "--failures", 0)
    result = invoke("run", short_scenario, "--out", out, *args)
    assert result.exit_code == 0, result.output
    assert json.loads((out / "config.json").read_text())["settings"]["method"] == (
        "splitting_is"
    )
    err = words(result.stderr)
    # max_levels=12 sets of 100 (the first of 800 on a plateau, two moves per
    # state after it), the moves and two refresh rounds at gamma and the final
    # stage: a bound; 7 times the sets (each replicate regrown twice, to 2 and
    # 4 times its particles) and 4 x 100 states moved and refreshed at gamma if
    # its levels run out, every move twice over after correlated chains:
    # (800 + 11 x 400) x 7 + 4 x (400 + 200) + 100
    assert (
        "plan: splitting + IS (subset simulation, 100 particles per level, p0 0.1, "
        "2 moves per state, regrown up to 2x, 2 refresh rounds, then IS 100 (4 "
        "components, "
        "defensive 0.1)): at most 3,500 rollouts (fewer if the levels reach "
        "gamma sooner; up to 38,900 if "
        "levels that run out are run again, larger, or slowly mixing chains move "
        "more); samples take at most about"
    ) in err
    # its first batch: the first replicate's first set, 50 particles
    assert "rollouts/s on the first 50: at most about" in err
    assert "for at most 3,450 more" in err
    assert_whole_at_80_columns(result.stdout)
    estimate = json.loads((out / "summary.json").read_text())["estimate"]
    n = estimate["n_evals"]
    assert n < 3500
    # the bar ends full at the rollouts the levels needed, not short of the bound
    assert f"{n}/{n}" in err and "/3500" not in err
    assert f"method splitting + IS, {estimate['n_evals']:,} rollouts" in words(
        result.stdout
    )
    details = estimate["details"]
    tables = words(result.stdout)
    assert "splitting + IS: Importance-sampling proposal" in tables
    assert "splitting + IS: Importance sampling vs subset simulation's own" in tables
    for g in ("1.0", "2.0"):  # subset simulation's own estimate, beside the IS one
        assert f"{details['splitting'][g]['p']:.3g}" in tables


def disk_figures(err):
    """The disk a rollout takes [B] as the plan estimates it, and as measured."""
    estimate = err.split("(an estimate: ")[1].split(" B a rollout")[0]
    measured = err.split("; disk: ")[1].split(" B a rollout")[0]
    return [float(x.replace(",", "")) for x in (measured, estimate)]


def test_the_plan_measures_the_disk_of_a_scenario_that_records_more(tmp_path):
    """The learned drivers' 404-d xi, stored: ten times the disk of the default."""
    scenario = shortened_scenario(tmp_path, 0.3, scenario="highway_default")
    args = ("--method", "ce", "--n-per-iter", 50, "--n-iter", 1, "--n-final", 50)
    args += ("--failures", 0)
    result = invoke(
        "run", scenario, "--out", tmp_path / "run", *args, "--store-full-samples"
    )
    assert result.exit_code == 0, result.output
    measured, estimate = disk_figures(words(result.stderr))
    assert estimate > 2000 and measured > 2000  # against 273 B without xi
    assert measured == pytest.approx(estimate, rel=0.15)


def test_the_plan_counts_the_rollouts_splitting_stores_in_full(tmp_path):
    """Its levels' points (xi too) are stored; its final stage leaves xi out."""
    scenario = shortened_scenario(tmp_path, 0.3, scenario="highway_default")
    args = ("--set", "n_particles=30", "--n-final", 30, "--gamma", 1.0)
    args += ("--gamma-test", "2.0", "--batch-size", 64, "--failures", 0)
    result = invoke("run", scenario, "--out", tmp_path / "run", *args)
    assert result.exit_code == 0, result.output
    err = words(result.stderr)
    estimates = err.split("(an estimate: ")[1].split(" B for one")[0]
    compact, full = (
        float(x.replace(",", "")) for x in estimates.split(" B a rollout, ")
    )
    assert compact < 400 < 2000 < full  # xi's 404 float32 columns
    # 12 sets of 30 (the first of 240 on a plateau, two moves a state after
    # it) and 2 x 30 moves at gamma in full, the final 30 without xi (the plan
    # before any regrowth)
    planned = err.split("samples take at most about ")[1].split(" on disk")[0]
    assert planned == "2 MB"  # (960 full + 30 compact) rows, about 2.2 MB
    assert 1.5e6 <= 960 * full + 30 * compact < 2.5e6
    measured = float(err.split("; disk: ")[1].split(" B a rollout")[0].replace(",", ""))
    assert measured == pytest.approx(full, rel=0.15)  # the first chunk: a level
    assert " B a rollout stored in full, at most about " in err.split("; disk: ")[1]


def test_json_is_one_document_on_stdout(short_scenario, tmp_path):
    out = tmp_path / "run"
    result = invoke("run", short_scenario, "--out", out, *RUN_ARGS, "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)  # progress and notes went to stderr
    assert doc["schema"] == "avrisk.result/1" and doc["command"] == "run"
    assert doc["horizon_s"] == 1.5 and doc["report"] == str(out / "report.html")
    answer = doc["answer"]
    assert answer["event"] == "P(min TTC <= 1 s) per 1.5-s rollout from P0"
    assert answer["trust"] in ("ok", "caution") and answer["run"] == "cross-entropy"
    (run,) = doc["runs"]
    summary = json.loads((out / "summary.json").read_text())
    audit = summary["estimate"]["details"]["audit"]["n_calls"]  # CE's check
    assert run["n_rollouts"] == 220 + audit and run["path"] == str(out)
    assert [g["gamma"] for g in run["by_gamma"]] == [0.5, 1.0, 2.0]
    assert {"p", "ci", "pareto_k", "trust", "reasons"} <= set(run["by_gamma"][0])
    # the report's diagnostic tables: CE's search, one row per iteration
    # and its audit's, one row
    search_table, audit_table = run["diagnostics"]
    assert (
        audit_table["title"].startswith("The audit") and len(audit_table["rows"]) == 1
    )
    assert search_table["columns"][0] == "CE iteration"
    assert len(search_table["rows"]) == 2
    assert all(len(row) == len(search_table["columns"]) for row in search_table["rows"])
    # 2 iterations of 60 do not take CE's level down to 1 s: said, and not trusted
    assert run["search"]["converged"] is False and run["search"]["reached_at"] is None
    assert answer["trust"] == "caution"
    assert answer["reasons"][0].startswith("the search did not reach min TTC <= 1 s")
    assert doc["comparison"] is None
    again = invoke("report", out, "--failures", 0, "--json")
    assert json.loads(again.stdout)["answer"] == answer


def test_compare_json_has_one_variance_ratio_per_threshold(short_scenario, tmp_path):
    out = tmp_path / "cmp"
    args = ("compare", short_scenario, "--out", out, *RUN_ARGS, "--reference-n", 150)
    result = invoke(*args, "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert [r["label"] for r in doc["runs"]] == [
        "cross-entropy",
        "naive MC, same budget",
        "naive MC reference",
    ]
    rows = doc["comparison"]
    assert [r["gamma"] for r in rows] == [0.5, 1.0, 2.0]
    for row in rows:
        assert {"variance_ratio", "rare_event_ratio", "p_from"} <= set(row)
        assert "variance_reduction" not in row
    assert "plan: " in result.stderr and "at most 1,070 rollouts in all" in words(
        result.stderr
    )
    report = invoke("report", out, "--failures", 0)
    assert_whole_at_80_columns(report.stdout)  # the tables of a comparison
    assert "rare-event" in report.stdout  # the comparison table
    tables = words(report.stdout)
    # the runs other than the answer's say why they are not trusted
    assert tables.count("trust at 1 s: caution (") == 2


def test_compare_gives_naive_sampling_the_rollouts_the_method_used(
    short_scenario, tmp_path
):
    # subset simulation's planned budget is a bound (max_levels full sets); naive
    # Monte Carlo gets what the run used, not the bound
    out = tmp_path / "cmp"
    args = ("compare", short_scenario, "--out", out, "--method", "splitting_is")
    args += ("--set", "n_particles=100", "--n-final", 100, "--gamma", 1.0)
    result = invoke(*args, "--gamma-test", "2.0", "--reference-n", 0, "--json")
    assert result.exit_code == 0, result.output
    runs = json.loads(result.stdout)["runs"]
    used = [run["n_rollouts"] for run in runs]
    assert [run["label"] for run in runs] == ["splitting + IS", "naive MC, same budget"]
    assert used[0] == used[1] < 100 * 12 + 100 + 100


def test_compare_defaults_finish_in_minutes():
    options = estimator_options("ce", {}, None, COMPARE_DEFAULTS)
    budget = get_estimator("ce", **options).budget()
    reference = inspect.signature(compare).parameters["reference_n"].default
    # CE's stages, and the bound of its audit (one particle per 50 final draws)
    assert budget == 20_000 + audit_bound(200) and reference == 50_000
    assert 2 * budget + reference <= 100_000  # ~3.5 min at 450 rollouts/s
    # the default, splitting_is: 2,000 particles per level, two moves a state,
    # two refresh rounds at gamma and 10,000 in its final stage; on
    # highway_default its levels reach 0.14 s in 4 sets (about 30,000
    # rollouts), within the bound the plan gives
    method = inspect.signature(compare).parameters["method"].default
    options = estimator_options(method, {}, None, COMPARE_DEFAULTS)
    splitting = get_estimator(method, **options)
    assert method == "splitting_is" and options == {"n_final": 10_000}
    s = splitting.settings
    assert s.n_moves == 2 and s.refresh_rounds == 2
    moved = s.n_moves * s.n_particles  # proposals a set after the first
    refreshed = s.refresh_rounds * s.n_particles  # one call a particle a round
    assert s.n_particles + 3 * moved + moved + refreshed + s.n_final == 32_000
    # the bound: 12 sets (the first of 8 N on a plateau), 7 times over where each
    # replicate runs out of levels twice and is regrown, 4 N states moved and
    # refreshed at gamma, every set after the first moved twice over after
    # correlated chains
    assert s.correlated_moves == 2
    levels = 8 * s.n_particles + 11 * 2 * moved
    at_gamma = 4 * (2 * moved + refreshed)
    assert splitting.budget() == 7 * levels + at_gamma + s.n_final == 786_000
    assert splitting.planned_budget() == 8 * s.n_particles + 11 * moved + moved + (
        refreshed + s.n_final
    )


def test_ctrl_c_says_how_to_resume_and_the_resumed_run_says_what_it_reused(
    short_scenario, tmp_path, monkeypatch
):
    out = tmp_path / "run"
    with ctrl_c_at_chunk(monkeypatch, 3):
        result = invoke("run", short_scenario, "--out", out, *RUN_ARGS)
    assert result.exit_code == 130
    assert "Traceback" not in result.output and "Aborted" not in result.output
    (line,) = [ln for ln in result.stderr.splitlines() if "Resume with:" in ln]
    command = shlex.split(line.split("Resume with: ")[1])
    assert command[:2] == ["avrisk", "run"]
    assert command[2] == str(short_scenario) and str(out) in command
    assert "--n-per-iter" in command and "--gamma-test" in command

    resumed = invoke(*command[1:])
    assert resumed.exit_code == 0, resumed.output
    summary = json.loads((out / "summary.json").read_text())
    simulated = summary["estimate"]["n_evals"] - 120  # the final stage, the audit
    assert (
        f"resumed: 120 rollouts reused from the earlier session, {simulated} "
        "simulated" in words(resumed.stderr)
    )
    assert summary["timing"]["rollouts_replayed"] == 120
    finished = invoke(*command[1:])
    assert "complete already in" in words(finished.stderr)
    assert "read back, nothing simulated" in words(finished.stderr)


LIGHT = [["--help"], ["scenarios"], ["scenarios", "show", "--help"]]
LIGHT += [[name, "--help"] for name in ("run", "compare", "report", "simulate")]
LIGHT += [[name, "--help"] for name in ("replay", "demo", "realism")]


@pytest.mark.parametrize("args", LIGHT, ids=" ".join)
def test_help_and_the_light_commands_start_without_torch(args):
    """Loading torch takes seconds: only the commands that simulate do it.

    Nor do they need a click of their own: Typer vendors its own from 0.2x on,
    and an install without the ``ray`` extra has no other (``make demo``'s).
    """
    code = (
        "import importlib.util, sys\n"
        "if importlib.util.find_spec('typer._click'):\n"
        "    sys.modules['click'] = None\n"
        "from avrisk.cli import main\n"
        "try:\n"
        "    main()\n"
        "finally:\n"
        "    print('torch loaded:', 'torch' in sys.modules, file=sys.stderr)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "torch loaded: False" in done.stderr


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_each_command_is_listed_by_its_docstring_and_loads_for_its_help(name):
    listing = words(invoke("--help").stdout)
    module, function = COMMANDS[name]
    summary = docstring(module, function).splitlines()[0]
    assert f"{name} {summary[:30]}" in listing
    result = invoke(name, "--help")
    assert result.exit_code == 0, result.output
    assert summary in words(result.stdout)


def test_the_bar_of_a_run_that_grows_past_its_plan_grows_with_it():
    from avrisk.cli.progress import RichRunMonitor

    console = Console(file=io.StringIO(), width=80, force_terminal=False)
    with RichRunMonitor(console, "splitting + IS") as monitor:
        monitor.start(100, "a plan of 100 rollouts")
        monitor.advance(80, replayed=False)
        monitor.advance(70, replayed=False)  # a replicate regrown: past the plan
        task = monitor._progress.tasks[0]
        assert task.total == task.completed == 150
