"""``avrisk run``, ``avrisk compare`` and ``avrisk report``: the main job.

``run`` estimates ``P0(min TTC <= gamma)`` for a scenario with any registered
estimator (``--method``; cross-entropy importance sampling by default) into a
run directory (resumable; see :mod:`avrisk.pipeline.store`) and writes its
report. ``compare`` runs a method, naive MC at its budget and a larger naive
reference side by side, as the paper's Table 1 and Fig. 2-3 do. ``report``
rebuilds the report of either.

The estimators' settings are options by name: those with a flag (``--rho``,
``--n-iter`` ...) and any other through ``--set NAME=VALUE``; a setting the
chosen estimator does not have is refused by name.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer
import yaml

from avrisk.assembly import ScenarioSimulator, SimulationObjective, param_layout
from avrisk.cli.backends import Address, Backend, BackendOption, Workers, open_evaluator
from avrisk.cli.common import (
    CliError,
    Device,
    check_output_folder,
    resumable,
    user_errors,
)
from avrisk.cli.readback import check_recorded, check_samples, read_config
from avrisk.cli.results import ratio_rows, show_results
from avrisk.cli.workflow import (
    EXPECTED,
    NAIVE_PART,
    REFERENCE_PART,
    check_thresholds,
    compare_runs,
    comparison_parts,
    cost_meter,
    execute,
    method_label,
    samples_directory,
    settings,
    write_run_report,
)
from avrisk.pipeline import RunSettings
from avrisk.pipeline.store import SAMPLES_FILE
from avrisk.rare import estimator_names
from avrisk.rare.estimator import estimator_class
from avrisk.scenario import load_spec, spec_from_dict

DEFAULT_SCENARIO = "highway_default"
#: Where the command line's defaults differ from an estimator's own.
CLI_DEFAULTS = {"n_iter": 20}
#: ``compare``'s: a budget that finishes in minutes on a laptop (CE 5 x 2,000
#: + 10,000 rollouts, as much naive MC and a reference of 50,000: 90,000
#: rollouts, about 3.5 minutes on one core on highway_default).
COMPARE_DEFAULTS = {"n_iter": 5, "n_per_iter": 2000, "n_final": 10_000}
COMPARE_REFERENCE = 50_000


Scenario = Annotated[
    str,
    typer.Argument(help="Scenario YAML file, or the name of a bundled scenario."),
]
Out = Annotated[Path, typer.Option("--out", help="Run directory (created or resumed).")]
Method = Annotated[
    str,
    typer.Option(help=f"Estimator: {', '.join(estimator_names())}."),
]
Gamma = Annotated[float, typer.Option(help="Threshold on the minimum TTC [s].")]
GammaTest = Annotated[
    str, typer.Option(help="Further thresholds [s], comma-separated, e.g. 0.1,0.2,0.3.")
]
Rho = Annotated[
    float | None,
    typer.Option(
        help="Elite quantile level, in (0, 1) [default: 0.01 for ce, 0.1 for mixture]."
    ),
]
Alpha = Annotated[
    float | None,
    typer.Option(help="CE smoothing of the update, in (0, 1] [default: 0.8]."),
]


def _budget(help_text: str, default: int) -> Any:
    """A CE budget option (``int | None``) whose help gives its default."""
    option = typer.Option(help=f"{help_text} [default: {default}].")
    return Annotated[int | None, option]


PER_ITER, ITERS, FINAL = (
    "CE samples per iteration",
    "CE search iterations",
    ("Rollouts of the final stage (naive: all)"),
)
NPerIter = _budget(PER_ITER, 5000)
NIter = _budget(ITERS, CLI_DEFAULTS["n_iter"])
NFinal = _budget(FINAL, 100_000)
CompareNPerIter = _budget(PER_ITER, COMPARE_DEFAULTS["n_per_iter"])
CompareNIter = _budget(ITERS, COMPARE_DEFAULTS["n_iter"])
CompareNFinal = _budget(FINAL, COMPARE_DEFAULTS["n_final"])
Seed = Annotated[int, typer.Option(min=0, help="Run seed.")]
BatchSize = Annotated[int, typer.Option(min=1, help="Rollouts simulated together.")]
Select = Annotated[
    str | None,
    typer.Option(help="CE proposal selection: quantile (default) or variance."),
]
Defensive = Annotated[
    float | None,
    typer.Option(
        help="Share of CE's final stage drawn from P0 instead of the proposal, "
        "in [0, 1): bounds every weight by 1/share (0, the paper's CE, for ce; "
        "0.1 for defensive)."
    ),
]
Set = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        help="Any setting of the estimator as NAME=VALUE (repeatable), e.g. "
        "--set interval=wilson.",
    ),
]
TargetPrecision = Annotated[
    float | None,
    typer.Option(
        "--target-rel-half-width",
        help="Stop the final stage once the 95% CI half-width at gamma is at most "
        "this fraction of p (e.g. 0.1).",
    ),
]
MaxRollouts = Annotated[
    int | None,
    typer.Option(min=1, help="Stop before the run's rollouts exceed this."),
]
MaxTime = Annotated[
    float | None,
    typer.Option(
        "--max-time",
        help="Stop the final stage after this many seconds of the run (the "
        "result then depends on the machine's speed).",
    ),
]
Failures = Annotated[int, typer.Option(min=0, help="Most likely failures to animate.")]
Json = Annotated[
    bool,
    typer.Option(
        "--json",
        help="Print the results as one JSON document on stdout (schema "
        "avrisk.result/1) instead of tables; progress stays on stderr.",
    ),
]


def _thresholds(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(t) for t in text.split(",") if t.strip())
    except ValueError:
        values = (math.nan,)
    if not all(map(math.isfinite, values)):
        raise CliError(
            f"--gamma-test must be finite numbers [s] separated by commas; got {text!r}"
        )
    return values


def _threshold(gamma: float) -> float:
    """``--gamma``, refused before any work unless a finite number."""
    if not math.isfinite(gamma):
        raise CliError(f"--gamma must be a finite number [s]; got {gamma}")
    return gamma


def estimator_options(
    method: str,
    flags: dict[str, Any],
    assignments: list[str] | None,
    cli_defaults: dict[str, Any] = CLI_DEFAULTS,
) -> dict[str, Any]:
    """The estimator's settings from its flags and ``--set NAME=VALUE``.

    Flags left unset take the command's defaults (``cli_defaults``, those of
    the estimator's settings that it has) or else the estimator's own; a
    flag or name the estimator does not have is a CliError naming it and
    listing the estimator's settings.
    """
    try:
        known = estimator_class(method).Settings.model_fields
    except KeyError as err:
        raise CliError(
            f"method must be one of {estimator_names()}; got {method!r}"
        ) from err
    given = {k: v for k, v in flags.items() if v is not None}
    for text in assignments or []:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise CliError(f"--set takes NAME=VALUE; got {text!r}")
        given[name.strip()] = yaml.safe_load(value)
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise CliError(
            f"{', '.join(unknown)}: not a setting of method {method!r} "
            f"(its settings: {', '.join(known)})"
        )
    defaults = {k: v for k, v in cli_defaults.items() if k in known}
    return {**defaults, **given}


#: The options of ``run`` and ``compare`` that are estimator settings by name.
ESTIMATOR_FLAGS = (
    "rho",
    "alpha",
    "n_per_iter",
    "n_iter",
    "n_final",
    "select",
    "defensive",
)


def _run_settings(
    method: str,
    gamma: float,
    gamma_test: str,
    seed: int,
    batch_size: int,
    assignments: list[str] | None,
    flags: dict[str, Any],
    cli_defaults: dict[str, Any] = CLI_DEFAULTS,
    **stopping: Any,
) -> RunSettings:
    """Run settings from a command's options; ``flags``: the estimator flags."""
    return settings(
        method,
        gamma=_threshold(gamma),
        gamma_test=_thresholds(gamma_test),
        seed=seed,
        batch_size=batch_size,
        **stopping,
        **estimator_options(method, flags, assignments, cli_defaults),
    )


def run(
    ctx: typer.Context,
    scenario: Scenario = DEFAULT_SCENARIO,
    out: Out = Path("runs/latest"),
    method: Method = "ce",
    gamma: Gamma = 0.14,
    gamma_test: GammaTest = "0.1,0.2,0.3",
    rho: Rho = None,
    alpha: Alpha = None,
    n_per_iter: NPerIter = None,
    n_iter: NIter = None,
    n_final: NFinal = None,
    seed: Seed = 0,
    batch_size: BatchSize = 4096,
    select: Select = None,
    defensive: Defensive = None,
    set_: Set = None,
    target_rel_half_width: TargetPrecision = None,
    max_rollouts: MaxRollouts = None,
    max_time: MaxTime = None,
    failures: Failures = 6,
    store_full_samples: Annotated[
        bool,
        typer.Option(
            help="Store every column of the samples table, the learned drivers' "
            "xi too (by default xi is drawn again, and checked, when read)."
        ),
    ] = False,
    device: Device = "cpu",
    workers: Workers = None,
    backend: BackendOption = Backend.local,
    address: Address = None,
    as_json: Json = False,
) -> None:
    """Estimate how likely the ego gets within gamma seconds of a collision.

    Prints the plan (rollouts, disk) first and the time it will take once the
    first chunk is simulated. Rerunning the same command after an
    interruption (Ctrl-C prints it) resumes the run; a finished run is read
    back and its report rebuilt. The run ends at its planned size or at the
    first stopping rule given, and says which.
    """
    with user_errors(*EXPECTED), resumable(ctx):
        check_output_folder(out)
        spec = load_spec(scenario)
        run_settings = _run_settings(
            method,
            gamma,
            gamma_test,
            seed,
            batch_size,
            set_,
            dict(
                rho=rho,
                alpha=alpha,
                n_per_iter=n_per_iter,
                n_iter=n_iter,
                n_final=n_final,
                select=select,
                defensive=defensive,
            ),
            rel_half_width=target_rel_half_width,
            max_rollouts=max_rollouts,
            max_seconds=max_time,
        )
        check_thresholds(spec, run_settings)
        objective = SimulationObjective(spec, device=device, allow_import=True)
        label = method_label(method)
        cost = cost_meter(spec, [(label, run_settings)], store_full=store_full_samples)
        with open_evaluator(objective, backend, workers, address) as evaluator:
            run_dir = execute(
                label,
                out,
                objective,
                spec.model_dump(mode="json"),
                run_settings,
                failures,
                evaluator,
                store_full=store_full_samples,
                cost=cost,
            )
        runs = [(label, run_dir)]
        report = write_run_report(
            out, runs, spec, failures, simulator=objective.simulator
        )
        show_results("run", runs, spec, as_json=as_json, report=report)


def compare(
    ctx: typer.Context,
    scenario: Scenario = DEFAULT_SCENARIO,
    out: Out = Path("runs/compare"),
    method: Method = "ce",
    gamma: Gamma = 0.14,
    gamma_test: GammaTest = "0.1,0.2,0.3",
    rho: Rho = None,
    alpha: Alpha = None,
    n_per_iter: CompareNPerIter = None,
    n_iter: CompareNIter = None,
    n_final: CompareNFinal = None,
    reference_n: Annotated[
        int, typer.Option(min=0, help="Rollouts of the naive reference run (0: none).")
    ] = COMPARE_REFERENCE,
    seed: Seed = 0,
    batch_size: BatchSize = 4096,
    select: Select = None,
    defensive: Defensive = None,
    set_: Set = None,
    failures: Failures = 6,
    device: Device = "cpu",
    workers: Workers = None,
    backend: BackendOption = Backend.local,
    address: Address = None,
    as_json: Json = False,
) -> None:
    """A method vs naive Monte Carlo on one scenario (paper's Table 1, Fig. 2-3).

    Runs the method (cross-entropy by default), naive MC with its total number
    of rollouts, and a larger naive reference, each in its own resumable
    directory under OUT, then writes OUT/report.html with the rare-event and
    variance ratios per threshold. The defaults (CE 5 x 2,000 + 10,000
    rollouts, a reference of 50,000) take minutes; the plan's cost is
    printed before the first rollout.
    """
    with user_errors(*EXPECTED), resumable(ctx):
        check_output_folder(out)
        tested = _run_settings(
            method,
            gamma,
            gamma_test,
            seed,
            batch_size,
            set_,
            dict(
                rho=rho,
                alpha=alpha,
                n_per_iter=n_per_iter,
                n_iter=n_iter,
                n_final=n_final,
                select=select,
                defensive=defensive,
            ),
            COMPARE_DEFAULTS,
        )
        compare_runs(
            scenario,
            out,
            tested,
            reference_n,
            failures,
            device,
            (backend, workers, address),
            as_json=as_json,
        )


def report(
    run_dir: Annotated[
        Path, typer.Argument(help="A directory made by run or compare.")
    ],
    failures: Failures = 6,
    scenario: Annotated[
        str | None,
        typer.Option(
            "--scenario",
            help="The run's scenario file, given again: needed only to animate "
            "failures without recorded traces of a scenario that names user code "
            "by import path.",
        ),
    ] = None,
    device: Device = "cpu",
    as_json: Json = False,
) -> None:
    """Rebuild the report of a finished run or comparison.

    Failures are animated from the traces recorded during the run; the run
    directory alone suffices (it never makes avrisk import code).
    """
    with user_errors(*EXPECTED):
        single = (run_dir / "config.json").is_file()
        parts = [] if single else comparison_parts(run_dir)
        if not single and not parts:
            raise CliError(f"{run_dir} holds no avrisk run (no config.json)")
        dirs = [("run", run_dir)] if single else parts
        for _, path in dirs:
            check_recorded(path)
        config = read_config(dirs[0][1])
        spec = spec_from_dict(config["scenario"], source=f"{dirs[0][1]}/config.json")
        simulator = None
        if scenario is not None:
            given = load_spec(scenario)
            if given.model_dump(mode="json") != config["scenario"]:
                raise CliError(
                    f"{scenario} is not the scenario of {run_dir} (they differ); "
                    "give the file the run was made with"
                )
            simulator = ScenarioSimulator(given, device=device, allow_import=True)
        elif not spec.import_paths():
            simulator = ScenarioSimulator(spec, device=device)
        layout = param_layout(spec)
        runs, by_name = [], {}
        for name, path in dirs:
            directory = samples_directory(path, spec)
            if not directory.is_complete:
                raise CliError(
                    f"{path} is not finished; rerun its command to resume it"
                )
            check_samples(directory.path / SAMPLES_FILE, layout.columns)
            label = method_label(directory.config()["settings"]["method"])
            runs.append((label if single else f"{label} ({name})", directory))
            by_name[name] = directory
        ref_dir = by_name.get(REFERENCE_PART)
        naive = by_name.get(NAIVE_PART)
        path = write_run_report(
            run_dir, runs, spec, failures, ref_dir, simulator=simulator
        )
        show_results(
            "report",
            runs,
            spec,
            as_json=as_json,
            ratios=None if naive is None else ratio_rows(runs[0][1], naive, ref_dir),
            has_reference=ref_dir is not None,
            report=path,
        )
