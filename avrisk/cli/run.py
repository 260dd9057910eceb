"""``avrisk run``, ``avrisk compare`` and ``avrisk report``: the main job.

``run`` estimates ``P0(min TTC <= gamma)`` for a scenario with any registered
estimator (``--method``; by default ``splitting_is``, importance sampling from
subset simulation's particles, the best of the coverage benchmark; ``ce`` is
the paper's cross-entropy) into a run directory (resumable; see
:mod:`avrisk.pipeline.store`) and writes its report. ``compare`` runs a
method, naive MC at its budget and a larger naive reference side by side, as
the paper's Table 1 and Fig. 2-3 do. ``report`` rebuilds the report of either.

The estimators' settings are options by name: those with a flag (``--rho``,
``--n-iter`` ...) and any other through ``--set NAME=VALUE``; a setting the
chosen estimator does not have is refused by name, with the methods that have
it (``--rho`` is cross-entropy's).

The simulator (torch) is imported by the commands' bodies, not by this module:
``--help`` shows the estimators' settings without it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from avrisk.api.backends import DEFAULT_BACKEND
from avrisk.cli.backends import Address, BackendOption, Workers
from avrisk.cli.common import (
    CliError,
    Device,
    check_output_folder,
    err_console,
    resumable,
    user_errors,
)
from avrisk.cli.estimator_options import (
    CLI_DEFAULTS,
    estimator_options,
    setting_option,
)
from avrisk.cli.progress import RichProgress
from avrisk.cli.results import show_comparison, show_results
from avrisk.pipeline import RunSettings
from avrisk.rare import estimator_names
from avrisk.rare.estimator import DEFAULT_METHOD

if TYPE_CHECKING:  # the simulator (torch) is loaded by the command that runs
    from avrisk.api.result import EstimationResult

DEFAULT_SCENARIO = "highway_default"
#: ``compare``'s: a budget that finishes in minutes on a laptop. splitting_is
#: keeps its own 2,000 particles per level (two moves a state, two refresh
#: rounds at gamma) and takes a final stage of 10,000: about 30,000 rollouts
#: on highway_default (its plan says at most 78,000, or 786,000 if levels that
#: run out are run again), as much naive MC and a reference of 50,000, about
#: 110,000 rollouts; CE 5 x 2,000 + 10,000 rollouts and its audit, 90,000.
COMPARE_DEFAULTS = {"n_iter": 5, "n_per_iter": 2000, "n_final": 10_000}
COMPARE_REFERENCE = 50_000


Scenario = Annotated[
    str,
    typer.Argument(help="Scenario YAML file, or the name of a bundled scenario."),
]
Out = Annotated[Path, typer.Option("--out", help="Run directory (created or resumed).")]
Method = Annotated[
    str,
    typer.Option(
        help=f"Estimator: {', '.join(estimator_names())}; ce is the paper's "
        "cross-entropy. The options below say which methods have them."
    ),
]
Gamma = Annotated[float, typer.Option(help="Threshold on the minimum TTC [s].")]
GammaTest = Annotated[
    str, typer.Option(help="Further thresholds [s], comma-separated, e.g. 0.1,0.2,0.3.")
]
Rho = setting_option(float, "rho", "CE search: elite quantile level, in (0, 1)")
Alpha = setting_option(float, "alpha", "CE search: smoothing of the update, in (0, 1]")
PER_ITER, ITERS, FINAL = (
    "CE search: samples per iteration",
    "CE search: iterations",
    "Rollouts of the final stage (naive: all)",
)
NPerIter = setting_option(int, "n_per_iter", PER_ITER)
NIter = setting_option(int, "n_iter", ITERS)
NFinal = setting_option(int, "n_final", FINAL)
CompareNPerIter = setting_option(int, "n_per_iter", PER_ITER, COMPARE_DEFAULTS)
CompareNIter = setting_option(int, "n_iter", ITERS, COMPARE_DEFAULTS)
CompareNFinal = setting_option(int, "n_final", FINAL, COMPARE_DEFAULTS)
Seed = Annotated[int, typer.Option(min=0, help="Run seed.")]
BatchSize = Annotated[int, typer.Option(min=1, help="Rollouts simulated together.")]
Select = setting_option(str, "select", "CE proposal selection: quantile or variance")
Defensive = setting_option(
    float,
    "defensive",
    "Share of P0 in the final stage's proposal, in [0, 1): bounds every weight "
    "by 1/share (0 is the paper's CE)",
)
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
Failures = Annotated[
    int,
    typer.Option(
        min=0,
        help="Dangerous rollouts the report shows and animates, the most realistic "
        "first: ranked by the lower of two percentiles under P0, their start's "
        "and their learned drivers'.",
    ),
]
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
    from avrisk.api.runs import settings

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
    method: Method = DEFAULT_METHOD,
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
    backend: BackendOption = DEFAULT_BACKEND,
    address: Address = None,
    as_json: Json = False,
) -> None:
    """Estimate how likely the ego gets within gamma seconds of a collision.

    By default with splitting_is (subset simulation, then importance sampling
    from its particles: about 30,000 rollouts on highway_default); --method
    ce is the paper's cross-entropy. Prints the plan (rollouts, disk; "at
    most" where the levels may end sooner) first and the time it will take
    once the first chunk is simulated. Rerunning the same command after an
    interruption (Ctrl-C prints it) resumes the run; a finished run is read
    back and its report rebuilt. The run ends at its planned size or at the
    first stopping rule given, and says which.
    """
    from avrisk.api.runs import EXPECTED, estimate_spec

    with user_errors(*EXPECTED), resumable(ctx):
        check_output_folder(out)
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
        result = estimate_spec(
            scenario,
            run_settings,
            out,
            failures=failures,
            store_full=store_full_samples,
            device=device,
            backend=(backend, workers, address),
            progress=RichProgress(err_console),
        )
        show_outcome(result, as_json)


def compare(
    ctx: typer.Context,
    scenario: Scenario = DEFAULT_SCENARIO,
    out: Out = Path("runs/compare"),
    method: Method = DEFAULT_METHOD,
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
    backend: BackendOption = DEFAULT_BACKEND,
    address: Address = None,
    as_json: Json = False,
) -> None:
    """A method vs naive Monte Carlo on one scenario (paper's Table 1, Fig. 2-3).

    Runs the method (splitting_is by default; ce for the paper's
    cross-entropy), naive MC with its total number of rollouts, and a larger
    naive reference, each in its own resumable directory under OUT, then
    writes OUT/report.html with the rare-event and variance ratios per
    threshold. The defaults (splitting_is: 2,000 particles per level and a
    final stage of 10,000, about 30,000 rollouts on highway_default; ce: 5 x
    2,000 + 10,000; a reference of 50,000) take minutes; the plan's cost is
    printed before the first rollout.
    """
    from avrisk.api.runs import EXPECTED, compare_runs

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
        result = compare_runs(
            scenario,
            out,
            tested,
            reference_n,
            failures,
            device,
            (backend, workers, address),
            progress=RichProgress(err_console),
        )
        show_outcome(result, as_json)


def report(
    run_dir: Annotated[
        Path, typer.Argument(help="A directory made by run, compare or ab.")
    ],
    failures: Annotated[
        int | None,
        typer.Option(
            min=0,
            help="Dangerous rollouts the report shows and animates, the most "
            "realistic first [default: 6; of an ab directory: the regressions and "
            "fixes ab animated, each].",
        ),
    ] = None,
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
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print the results as one JSON document on stdout (schema "
            "avrisk.result/1; of an ab directory avrisk.ab/1) instead of tables.",
        ),
    ] = False,
) -> None:
    """Rebuild the report of a finished run, comparison or A/B comparison.

    Failures are animated from the traces recorded during the run; the run
    directory alone suffices (it never makes avrisk import code). Of an ab
    directory, ab_report.html and ab.json are written again as ab wrote them,
    and its line printed.
    """
    from avrisk.api.ab import ABResult
    from avrisk.api.rebuild import rebuild
    from avrisk.api.runs import EXPECTED

    with user_errors(*EXPECTED):
        result = rebuild(run_dir, failures, scenario, device)
        if isinstance(result, ABResult):
            show_comparison(result, as_json)
        else:
            show_outcome(result, as_json)


def show_outcome(result: EstimationResult, as_json: bool) -> None:
    """The results of a comparison or a rebuilt report: tables, or JSON."""
    show_results(
        result.command,
        result.runs,
        result.spec,
        as_json=as_json,
        ratios=result.ratios,
        has_reference=result.has_reference,
        report=result.report,
    )
