import json

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from avrisk.cli.app import app
from tests.scenario_files import shortened_scenario

SUMMARY_KEYS = {"schema", "method", "settings", "estimate", "timing", "versions"}


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory):
    """The bundled scenario with a 1.5 s horizon, to keep CI fast."""
    directory = tmp_path_factory.mktemp("scenario")
    return shortened_scenario(directory, 1.5, name="highway_short")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


CE_ARGS = (
    "--method",
    "ce",
    "--rho",
    0.1,
    "--n-per-iter",
    60,
    "--n-iter",
    2,
    "--n-final",
    100,
    "--gamma",
    1.0,
    "--gamma-test",
    "0.5,2.0",
    "--batch-size",
    64,
    "--failures",
    1,
)


def test_run_writes_a_complete_run_directory_with_a_report(short_scenario, tmp_path):
    out = tmp_path / "run"
    result = invoke("run", short_scenario, "--out", out, *CE_ARGS)
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} >= {
        "config.json",
        "checkpoint.json",
        "samples.parquet",
        "summary.json",
        "report.html",
        "plots",
    }
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary) and summary["schema"] == "avrisk.summary/1"
    assert [g["gamma"] for g in summary["estimate"]["by_gamma"]] == [1.0, 0.5, 2.0]
    table = pq.read_table(out / "samples.parquet")
    audit = summary["estimate"]["details"]["audit"]  # CE's check, after its stages
    assert table.num_rows == 2 * 60 + 100 + audit["n_calls"]
    for col in (
        "veh0.s",
        "veh5.speed",
        "seed",
        "log_p0",
        "log_p_proposal",
        "weight",
        "f",
        "crash",
        "offroad",
        "reversing",
        "steps",
        "stage",
        "iteration",
    ):
        assert col in table.column_names, col


def test_a_defensive_final_stage_is_recorded_and_bounds_its_weights(
    short_scenario, tmp_path
):
    out = tmp_path / "run"
    result = invoke("run", short_scenario, "--out", out, *CE_ARGS, "--defensive", 0.25)
    assert result.exit_code == 0, result.output
    config = json.loads((out / "config.json").read_text())
    assert config["settings"]["defensive"] == 0.25
    table = pq.read_table(out / "samples.parquet", columns=["stage", "weight"])
    final = table.column("stage").to_numpy() == 0
    weights = table.column("weight").to_numpy()[final]
    assert weights.size == 100 and weights.max() <= 4.0 + 1e-9
    # A run without it keeps the paper's plain proposal and records no setting.
    plain = tmp_path / "plain"
    assert invoke("run", short_scenario, "--out", plain, *CE_ARGS).exit_code == 0
    settings = json.loads((plain / "config.json").read_text())["settings"]
    assert "defensive" not in settings


def test_rerunning_run_reads_back_the_same_summary(short_scenario, tmp_path):
    out = tmp_path / "run"
    assert invoke("run", short_scenario, "--out", out, *CE_ARGS).exit_code == 0
    first = json.loads((out / "summary.json").read_text())
    assert invoke("run", short_scenario, "--out", out, *CE_ARGS).exit_code == 0
    assert json.loads((out / "summary.json").read_text()) == first
    assert invoke("report", out, "--failures", 0).exit_code == 0


def test_run_refuses_a_directory_holding_a_different_run(short_scenario, tmp_path):
    out = tmp_path / "run"
    assert invoke("run", short_scenario, "--out", out, *CE_ARGS).exit_code == 0
    result = invoke("run", short_scenario, "--out", out, *CE_ARGS, "--seed", 5)
    assert result.exit_code == 2
    assert "holds a different run" in result.output and "settings.seed" in result.output


def test_bad_input_gives_one_clear_line_and_leaves_nothing(tmp_path):
    out = tmp_path / "run"
    missing = invoke("run", tmp_path / "nope.yaml", "--out", out)
    assert missing.exit_code == 2 and "error:" in missing.output
    bad_rho = invoke("run", "highway_idm", "--out", out, "--method", "ce", "--rho", 1.5)
    assert (
        bad_rho.exit_code == 2 and "rho: Input should be less than 1" in bad_rho.output
    )
    bad_gamma = invoke("run", "highway_idm", "--out", out, "--gamma-test", "0.1,x")
    assert bad_gamma.exit_code == 2 and "--gamma-test" in bad_gamma.output
    assert not out.exists()
    assert "Traceback" not in missing.output + bad_rho.output + bad_gamma.output


def test_every_registered_method_is_offered_and_foreign_settings_refused(tmp_path):
    help_text = " ".join(invoke("run", "--help").output.split())
    assert "ce, defensive, mixture, naive, splitting" in help_text
    assert "[default: splitting_is]" in help_text
    # each setting's default per method that has it
    assert "[default: 10000 for splitting_is; 100000 for ce, defensive" in help_text
    assert "[default: 0.01 for ce, defensive; 0.1 for mixture]" in help_text
    out = tmp_path / "run"
    foreign = invoke(
        "run", "highway_idm", "--out", out, "--method", "naive", "--rho", 0.1
    )
    assert foreign.exit_code == 2
    assert "rho: not a setting of method 'naive'" in foreign.output
    assert "its settings: n_final, interval" in foreign.output
    # a cross-entropy flag with the default method: which method it belongs to
    ce_flags = invoke("run", "highway_idm", "--out", out, "--rho", 0.2, "--n-iter", 3)
    assert ce_flags.exit_code == 2 and ce_flags.output.count("\n") == 1
    assert " ".join(ce_flags.output.split()) == (
        "error: --n-iter, --rho: not settings of method 'splitting_is', the default "
        "(--n-iter, --rho belong to ce, defensive, mixture: choose one with "
        "--method); its settings: n_particles, p0, p0_max, max_levels, n_moves, "
        "initial_beta, min_survivors, plateau_draws, replicates, regrow, "
        "correlated_moves, max_calls, n_final, n_components, defensive, "
        "min_weight, shift, fit_variances, moves_at_gamma, refresh_rounds, "
        "more_replicates"
    )
    by_name = invoke(
        "run", "highway_idm", "--out", out, "--method", "ce", "--set", "n_particles=9"
    )
    assert by_name.exit_code == 2 and (
        "error: n_particles: not a setting of method 'ce' (n_particles belongs to "
        "splitting, splitting_is: choose one with --method)"
    ) in " ".join(by_name.output.split())
    # a name no method has: the closest setting, the method's own first
    for given, hint in [
        ("n_particle=1000", "(did you mean n_particles?)"),
        ("n_iters=3", "(did you mean n_iter, a setting of ce, defensive, mixture? "),
        ("zzz=1", "(zzz is no method's setting)"),
    ]:
        misspelt = invoke("run", "highway_idm", "--out", out, "--set", given)
        assert misspelt.exit_code == 2 and hint in " ".join(misspelt.output.split())
    unknown = invoke("run", "highway_idm", "--out", out, "--method", "splitz")
    assert unknown.exit_code == 2 and "method must be one of" in unknown.output
    bad_set = invoke("run", "highway_idm", "--out", out, "--set", "rho")
    assert bad_set.exit_code == 2 and "--set takes NAME=VALUE" in bad_set.output
    assert not out.exists()


def test_set_passes_any_setting_by_name(short_scenario, tmp_path):
    out = tmp_path / "run"
    args = ("--method", "naive", "--n-final", 50, "--gamma", 1.0, "--failures", 0)
    result = invoke(
        "run", short_scenario, "--out", out, *args, "--set", "interval=wilson"
    )
    assert result.exit_code == 0, result.output
    settings = json.loads((out / "config.json").read_text())["settings"]
    assert settings["interval"] == "wilson" and settings["n_final"] == 50


def test_the_defensive_method_defaults_to_a_tenth_of_p0(short_scenario, tmp_path):
    out = tmp_path / "run"
    result = invoke(
        "run", short_scenario, "--out", out, *CE_ARGS, "--method", "defensive"
    )
    assert result.exit_code == 0, result.output
    settings = json.loads((out / "config.json").read_text())["settings"]
    assert settings["method"] == "defensive" and settings["defensive"] == 0.1


def test_naive_run_with_zero_hits_reports_an_upper_bound(short_scenario, tmp_path):
    out = tmp_path / "naive"
    result = invoke(
        "run",
        short_scenario,
        "--out",
        out,
        "--method",
        "naive",
        "--n-final",
        50,
        "--gamma",
        0.001,
        "--gamma-test",
        "",
        "--failures",
        0,
    )
    assert result.exit_code == 0, result.output
    est = json.loads((out / "summary.json").read_text())["estimate"]
    assert est["n_hits"] == 0 and est["p"] == 0.0
    assert est["ci"][1] == pytest.approx(1 - 0.025 ** (1 / 50))


def test_report_of_a_directory_without_a_run_is_an_error(tmp_path):
    result = invoke("report", tmp_path)
    assert result.exit_code == 2 and "holds no avrisk run" in result.output


def test_compare_runs_ce_naive_and_reference_then_reports_them(
    short_scenario, tmp_path
):
    out = tmp_path / "cmp"
    result = invoke(
        "compare", short_scenario, "--out", out, *CE_ARGS, "--reference-n", 150
    )
    assert result.exit_code == 0, result.output
    ce = json.loads((out / "ce" / "summary.json").read_text())["estimate"]
    used = 220 + ce["details"]["audit"]["n_calls"]  # naive MC gets what CE used
    for part, n in (("ce", used), ("naive", used), ("reference", 150)):
        summary = json.loads((out / part / "summary.json").read_text())
        assert summary["estimate"]["n_evals"] == n
    assert "cross-entropy against naive Monte Carlo" in result.output
    assert "rare-event" in result.output and "variance" in result.output
    html = (out / "report.html").read_text()
    assert "Cross-entropy vs naive Monte Carlo" in html
    assert "Runs compared at gamma" in html
    assert (out / "plots" / "comparison.png").is_file()
    assert invoke("report", out, "--failures", 0).exit_code == 0


def test_a_run_is_stamped_and_refuses_to_resume_with_other_weights(
    short_scenario, tmp_path
):
    out = tmp_path / "run"
    args = ("--method", "naive", "--n-final", 50, "--gamma", 1.0, "--failures", 0)
    assert invoke("run", short_scenario, "--out", out, *args).exit_code == 0
    summary = json.loads((out / "summary.json").read_text())
    defines = summary["provenance"]["defines_p"]
    assert len(defines["scenario_sha256"]) == 64
    assert defines["weights_sha256"] == {}  # IDM traffic: no learned weights
    assert summary["provenance"]["computed_with"]["precision"] == "float32"
    config = json.loads((out / "config.json").read_text())
    config["defines_p"]["weights_sha256"] = {"driver_net.npz": "0" * 64}
    (out / "config.json").write_text(json.dumps(config))
    again = invoke("run", short_scenario, "--out", out, *args)
    assert again.exit_code == 2
    assert "differs in: defines_p.weights_sha256" in again.output


def test_a_stopping_rule_is_recorded_and_reported(short_scenario, tmp_path):
    out = tmp_path / "run"
    args = ("--method", "naive", "--n-final", 20_000, "--gamma", 2.0, "--failures", 0)
    result = invoke("run", short_scenario, "--out", out, *args, "--max-rollouts", 9000)
    assert result.exit_code == 0, result.output
    assert "stopped by its max rollouts rule after 8,192 rollouts" in result.output
    settings = json.loads((out / "config.json").read_text())["settings"]
    assert settings["max_rollouts"] == 9000
    assert json.loads((out / "summary.json").read_text())["estimate"]["n_evals"] == 8192
