"""``avrisk run``, ``avrisk compare`` and ``avrisk report``: the main job.

``run`` estimates ``P0(min TTC <= gamma)`` for a scenario with naive Monte
Carlo or cross-entropy importance sampling into a run directory (resumable;
see :mod:`avrisk.pipeline.store`) and writes its report. ``compare`` runs CE,
naive MC at CE's budget and a larger naive reference side by side, as the
paper's Table 1 and Fig. 2-3 do. ``report`` rebuilds the report of either.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from avrisk.assembly import SimulationObjective, base_distribution
from avrisk.cli.app import app
from avrisk.cli.common import CliError, err_console, out_console, user_errors
from avrisk.cli.progress import RichRunMonitor
from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.rare import InvalidOutputError
from avrisk.rare.cross_entropy import SELECTION_RULES
from avrisk.report.animate import animate_samples
from avrisk.report.html import write_report
from avrisk.report.plots import UNRELIABLE_MARK, UNRELIABLE_NOTE, comparison_rows
from avrisk.scenario import ScenarioSpecError, load_spec
from avrisk.scenario.spec import spec_from_dict

EXPECTED = (ScenarioSpecError, RunDirectoryError, InvalidOutputError)
DEFAULT_SCENARIO = "highway_default"
COMPARE_PARTS = ("ce", "naive", "reference")
#: How a run of each method is labelled in tables and reports.
METHOD_LABELS = {"ce": "cross-entropy", "naive": "naive Monte Carlo"}


Scenario = Annotated[
    str,
    typer.Argument(help="Scenario YAML file, or the name of a bundled scenario."),
]
Out = Annotated[Path, typer.Option("--out", help="Run directory (created or resumed).")]
Gamma = Annotated[float, typer.Option(help="Threshold on the minimum TTC [s].")]
GammaTest = Annotated[
    str, typer.Option(help="Further thresholds [s], comma-separated, e.g. 0.1,0.2,0.3.")
]
Rho = Annotated[float, typer.Option(help="CE quantile level, in (0, 1).")]
Alpha = Annotated[float, typer.Option(help="CE smoothing of the update, in (0, 1].")]
NPerIter = Annotated[int, typer.Option(min=1, help="CE samples per iteration.")]
NIter = Annotated[int, typer.Option(min=0, help="CE search iterations.")]
NFinal = Annotated[int, typer.Option(min=1, help="Rollouts of the final stage.")]
Seed = Annotated[int, typer.Option(min=0, help="Run seed.")]
BatchSize = Annotated[int, typer.Option(min=1, help="Rollouts simulated together.")]
Select = Annotated[
    str,
    typer.Option(help=f"CE proposal selection: {', '.join(sorted(SELECTION_RULES))}."),
]
Defensive = Annotated[
    float,
    typer.Option(
        help="Share of CE's final stage drawn from P0 instead of the proposal, "
        "in [0, 1): bounds every weight by 1/share (0: the paper's CE)."
    ),
]
Failures = Annotated[int, typer.Option(min=0, help="Most likely failures to animate.")]
Device = Annotated[str, typer.Option(help="Torch device of the simulator.")]


def _thresholds(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise CliError(
            f"--gamma-test must be numbers separated by commas; got {text!r}"
        ) from None


def _settings(**kwargs: Any) -> RunSettings:
    try:
        return RunSettings(**kwargs)
    except ValueError as err:
        raise CliError(str(err)) from None


def _execute(
    label: str,
    out: Path,
    objective: SimulationObjective,
    spec_json: dict[str, Any],
    settings: RunSettings,
) -> RunDirectory:
    run_dir = RunDirectory(out, objective.layout.columns)
    base = base_distribution(objective.simulator.spec)
    with RichRunMonitor(err_console, label) as monitor:
        run_estimation(
            run_dir,
            base,
            objective,
            settings,
            context={"scenario": spec_json},
            monitor=monitor,
        )
    return run_dir


def _print_summary(runs: list[tuple[str, RunDirectory]]) -> None:
    table = Table(title="P(min TTC <= gamma)")
    columns = ("run", "gamma [s]", "p", "stderr", "95% CI", "hits", "ESS", "Pareto k")
    for col in (*columns, "rollouts"):
        table.add_column(escape(col), justify="left" if col == "run" else "right")
    for label, run_dir in runs:
        est = run_dir.summary()["estimate"]
        for g in sorted(est["by_gamma"], key=lambda g: g["gamma"]):
            table.add_row(
                label,
                f"{g['gamma']:g}",
                f"{g['p']:.3g}",
                f"{g['stderr']:.2g}",
                f"{g['ci'][0]:.2g}..{g['ci'][1]:.2g}",
                str(g["n_hits"]),
                f"{g['ess'] or 0:.1f}",
                "-" if g.get("pareto_k") is None else f"{g['pareto_k']:.2f}",
                f"{est['n_evals']:,}",
            )
    out_console.print(table)


def _report(
    out: Path,
    runs: list[tuple[str, RunDirectory]],
    objective: SimulationObjective,
    failures: int,
    reference: RunDirectory | None = None,
) -> Path:
    spec = objective.simulator.spec
    failures_from = next(
        (d for label, d in runs if label.startswith("cross")), runs[0][1]
    )
    path = write_report(
        out,
        runs,
        title=f"avrisk: {spec.name}",
        subtitle=spec.description or "",
        reference=reference,
        failures_from=failures_from,
        n_failures=failures,
        param_names=objective.layout.columns,
        animate=lambda row, p: animate_samples(objective.simulator, [row], p),
    )
    err_console.print(f"report: {path}")
    return path


@app.command()
def run(
    scenario: Scenario = DEFAULT_SCENARIO,
    out: Out = Path("runs/latest"),
    method: Annotated[str, typer.Option(help="'ce' or 'naive'.")] = "ce",
    gamma: Gamma = 0.14,
    gamma_test: GammaTest = "0.1,0.2,0.3",
    rho: Rho = 0.01,
    alpha: Alpha = 0.8,
    n_per_iter: NPerIter = 5000,
    n_iter: NIter = 20,
    n_final: NFinal = 100_000,
    seed: Seed = 0,
    batch_size: BatchSize = 4096,
    select: Select = "quantile",
    defensive: Defensive = 0.0,
    failures: Failures = 6,
    device: Device = "cpu",
) -> None:
    """Estimate how likely the ego gets within gamma seconds of a collision.

    Rerunning the same command after an interruption resumes the run; a
    finished run is read back and its report rebuilt.
    """
    with user_errors(*EXPECTED):
        spec = load_spec(scenario)
        settings = _settings(
            method=method,
            gamma=gamma,
            gamma_test=_thresholds(gamma_test),
            rho=rho,
            alpha=alpha,
            n_per_iter=n_per_iter,
            n_iter=n_iter,
            n_final=n_final,
            seed=seed,
            batch_size=batch_size,
            select=select,
            defensive=defensive,
        )
        objective = SimulationObjective(spec, device=device)
        label = METHOD_LABELS[method]
        run_dir = _execute(
            label, out, objective, spec.model_dump(mode="json"), settings
        )
        _print_summary([(label, run_dir)])
        _report(out, [(label, run_dir)], objective, failures)


def compare_runs(
    spec_name: str,
    out: Path,
    ce: RunSettings,
    reference_n: int,
    failures: int,
    device: str,
) -> Path:
    """CE, naive MC at CE's budget and a naive reference into ``out``; report."""
    spec = load_spec(spec_name)
    objective = SimulationObjective(spec, device=device)
    spec_json = spec.model_dump(mode="json")
    shared = dict(gamma=ce.gamma, gamma_test=ce.gamma_test, batch_size=ce.batch_size)
    plan = [
        (METHOD_LABELS["ce"], out / "ce", ce),
        (
            "naive MC, same budget",
            out / "naive",
            _settings(
                method="naive", n_final=ce.total_rollouts, seed=ce.seed + 1, **shared
            ),
        ),
    ]
    if reference_n:
        plan.append(
            (
                "naive MC reference",
                out / "reference",
                _settings(
                    method="naive", n_final=reference_n, seed=ce.seed + 2, **shared
                ),
            )
        )
    runs = [
        (label, _execute(label, path, objective, spec_json, s))
        for label, path, s in plan
    ]
    _print_summary(runs)
    reference = runs[2][1] if reference_n else None
    _print_ratios(runs[0][1], runs[1][1], reference)
    return _report(out, runs, objective, failures, reference)


def _print_ratios(
    ce: RunDirectory, naive: RunDirectory, reference: RunDirectory | None
) -> None:
    """CE against naive MC at the same budget, per threshold (paper's Fig. 2-3)."""
    naive_hits = {
        g["gamma"]: g["n_hits"] for g in naive.summary()["estimate"]["by_gamma"]
    }
    rows = comparison_rows(
        ce.summary()["estimate"],
        reference.summary()["estimate"] if reference is not None else None,
    )
    caption = (
        "Expected naive hits and variance p(1-p)/n use p from the "
        + ("naive reference run." if reference is not None else "CE estimate.")
        + "\nThe variance ratio trusts CE's own standard error; the spread of CE "
        "over seeds (benchmarks/ce_vs_naive.py) is the stricter test."
    )
    if not all(row["reliable"] for row in rows):
        caption += "\n" + UNRELIABLE_NOTE + "."
    table = Table(
        title="CE against naive Monte Carlo with the same number of rollouts",
        caption=escape(caption),
    )
    for col in (
        "gamma [s]",
        "p used",
        "CE hits",
        "naive hits (seen)",
        "naive hits (expected)",
        "rare-event ratio",
        "variance ratio",
    ):
        table.add_column(escape(col), justify="right")
    for row in rows:
        table.add_row(
            f"{row['gamma']:g}",
            f"{row['p']:.3g}",
            str(row["ce_hits"]),
            str(naive_hits.get(row["gamma"], "")),
            f"{row['naive_hits_expected']:.1f}",
            f"{row['rare_event_ratio']:.1f}x",
            f"{row['variance_ratio']:.1f}x"
            + ("" if row["reliable"] else UNRELIABLE_MARK),
        )
    out_console.print(table)


@app.command()
def compare(
    scenario: Scenario = DEFAULT_SCENARIO,
    out: Out = Path("runs/compare"),
    gamma: Gamma = 0.14,
    gamma_test: GammaTest = "0.1,0.2,0.3",
    rho: Rho = 0.01,
    alpha: Alpha = 0.8,
    n_per_iter: NPerIter = 5000,
    n_iter: NIter = 20,
    n_final: NFinal = 100_000,
    reference_n: Annotated[
        int, typer.Option(min=0, help="Rollouts of the naive reference run (0: none).")
    ] = 1_000_000,
    seed: Seed = 0,
    batch_size: BatchSize = 4096,
    select: Select = "quantile",
    defensive: Defensive = 0.0,
    failures: Failures = 6,
    device: Device = "cpu",
) -> None:
    """Cross-entropy vs naive Monte Carlo on one scenario (paper's Table 1, Fig. 2-3).

    Runs CE, naive MC with CE's total number of rollouts, and a larger naive
    reference, each in its own resumable directory under OUT, then writes
    OUT/report.html with the rare-event and variance ratios per threshold.
    """
    with user_errors(*EXPECTED):
        ce = _settings(
            method="ce",
            gamma=gamma,
            gamma_test=_thresholds(gamma_test),
            rho=rho,
            alpha=alpha,
            n_per_iter=n_per_iter,
            n_iter=n_iter,
            n_final=n_final,
            seed=seed,
            batch_size=batch_size,
            select=select,
            defensive=defensive,
        )
        compare_runs(scenario, out, ce, reference_n, failures, device)


@app.command()
def report(
    run_dir: Annotated[
        Path, typer.Argument(help="A directory made by run or compare.")
    ],
    failures: Failures = 6,
    device: Device = "cpu",
) -> None:
    """Rebuild the report of a finished run or comparison."""
    with user_errors(*EXPECTED):
        parts = [
            (p, run_dir / p)
            for p in COMPARE_PARTS
            if (run_dir / p / "config.json").is_file()
        ]
        single = (run_dir / "config.json").is_file()
        if not single and not parts:
            raise CliError(f"{run_dir} holds no avrisk run (no config.json)")
        dirs = [("run", run_dir)] if single else [(name, path) for name, path in parts]
        config = json.loads((dirs[0][1] / "config.json").read_text())
        spec = spec_from_dict(config["scenario"], source=f"{dirs[0][1]}/config.json")
        objective = SimulationObjective(spec, device=device)
        runs = []
        for name, path in dirs:
            directory = RunDirectory(path, objective.layout.columns)
            if not directory.is_complete:
                raise CliError(
                    f"{path} is not finished; rerun its command to resume it"
                )
            method = directory.config()["settings"]["method"]
            label = METHOD_LABELS[method]
            runs.append((label if single else f"{label} ({name})", directory))
        reference = dict(parts).get("reference")
        ref_dir = (
            RunDirectory(reference, objective.layout.columns) if reference else None
        )
        _print_summary(runs)
        _report(run_dir, runs, objective, failures, ref_dir)
