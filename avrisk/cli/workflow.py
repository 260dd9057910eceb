"""What ``run``, ``compare``, ``report`` and ``demo`` share: runs, costs, reports.

Every function here works for any registered estimator
(:func:`avrisk.rare.estimator_names`): labels, progress lines and report
sections come from the estimator itself.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.markup import escape

from avrisk.assembly import (
    FAILURES_FILE,
    MECHANISMS,
    FailureRecorder,
    ScenarioSimulator,
    SimulationObjective,
    base_distribution,
    camera_frames,
    camera_from_spec,
    param_layout,
    read_failure_traces,
    scenario_typicality,
)
from avrisk.cli.backends import Backend, open_evaluator
from avrisk.cli.common import CliError, err_console, write_failures
from avrisk.cli.progress import CostMeter, PlannedRun, RichRunMonitor
from avrisk.cli.readback import check_recorded
from avrisk.cli.results import ratio_rows, show_results
from avrisk.extras import MissingExtraError
from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.pipeline.provenance import (
    ProvenanceMismatchError,
    check_same_definition,
    stamp,
)
from avrisk.pipeline.regenerate import RegenerationError
from avrisk.pipeline.repeatability import NotRepeatableError, ReplayCheck
from avrisk.pipeline.store import estimated_row_bytes
from avrisk.rare import InvalidOutputError
from avrisk.rare.estimator import TooManyFailuresError, estimator_class
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.parallel import WorkerError
from avrisk.rare.splitting import SplittingError
from avrisk.registry import ComponentError
from avrisk.report.animate import animate_rollouts, animate_samples
from avrisk.report.camera_video import animate_camera_rollout
from avrisk.report.html import write_report
from avrisk.scenario import ScenarioSpec, ScenarioSpecError, load_spec

#: Failures reported as one red line (no traceback).
EXPECTED = (
    ScenarioSpecError,
    ComponentError,
    MissingExtraError,
    RunDirectoryError,
    RegenerationError,
    InvalidOutputError,
    TooManyFailuresError,
    ProvenanceMismatchError,
    NotRepeatableError,
    WorkerError,
    SplittingError,
)
#: Sub-directories of a comparison besides the tested method's own.
NAIVE_PART, REFERENCE_PART = "naive", "reference"


def method_label(method: str) -> str:
    """The human name of a registered estimator (``"cross-entropy"``)."""
    return estimator_class(method).label


def settings(method: str, **kwargs: Any) -> RunSettings:
    """Validated run settings, or a one-line CliError."""
    try:
        return RunSettings(method, **kwargs)
    except (KeyError, ValueError) as err:
        raise CliError(str(err).strip('"')) from None


#: Registered safety measures that are never negative (a time to collision).
NON_NEGATIVE_MEASURES = ("min_ttc", "min_box_ttc")


def check_thresholds(spec: ScenarioSpec, run_settings: RunSettings) -> None:
    """Refuse a negative threshold on a measure that is never negative.

    ``P(min TTC <= gamma)`` is 0 for every ``gamma < 0``: such a run would
    spend its rollouts to report a certain zero. A measure of the user's own
    may be negative, and is not checked.
    """
    if spec.safety.measure not in NON_NEGATIVE_MEASURES:
        return
    negative = [g for g in (run_settings.gamma, *run_settings.gamma_test) if g < 0]
    if negative:
        raise CliError(
            f"threshold {negative[0]:g} s is negative, but {spec.safety.measure} "
            "(a time to collision) never is: P(min TTC <= gamma) would be 0; "
            "give --gamma and --gamma-test >= 0"
        )


def execute(
    label: str,
    out: Path,
    objective: SimulationObjective,
    spec_json: dict[str, Any],
    run_settings: RunSettings,
    failures: int,
    evaluator: Evaluator | None = None,
    *,
    store_full: bool = False,
    cost: CostMeter | None = None,
) -> RunDirectory:
    """Run (or resume, or read back) one estimation into ``out`` with progress.

    The traces of the ``failures`` most likely dangerous rollouts are recorded
    as the run goes (``out/failures.parquet``), for its report (none: no
    traces are recorded). ``evaluator``: where the rollouts are simulated
    (default: in this process); worker processes record no traces (the
    report simulates the failures it shows again). ``store_full``: keep every
    column of the samples (else the learned drivers' ``xi`` is drawn again
    when read). A resumed run first replays a few recorded rollouts, in this
    process, and stops if the ego gives other results (it changed since); a
    new run does so with fresh draws where an actor does not vouch for its
    repeatability (an external AV, :attr:`ScenarioSimulator.deterministic`):
    an AV that ignores its seeds (:mod:`avrisk.pipeline.repeatability`).
    ``cost``: told of every rollout, to print the plan and the time measured
    on the first chunk (:class:`CostMeter`). A run that was complete already
    says it was read back; one that resumed, how many rollouts it reused.
    """
    check_recorded(out)  # a damaged config or summary: one line, not a traceback
    base = base_distribution(objective.simulator.spec)
    run_dir = samples_directory(out, objective.simulator.spec, store_full=store_full)
    definition = objective.definition()
    plain = objective
    if failures and evaluator is None:
        typical = scenario_typicality(objective.simulator.spec)

        def rank(x: np.ndarray) -> np.ndarray:
            return typical.rank(x[:, : typical.n_situation], base.log_prob(x))

        recorder = FailureRecorder(
            out / FAILURES_FILE, run_settings.gamma, failures, rank
        )
        objective = objective.recording(recorder)
    resume = (
        "what was recorded is kept: free space (or fix the folder) and rerun the "
        "same command to resume"
    )
    monitor = RichRunMonitor(err_console, label, cost)
    with write_failures(out, resume), monitor:
        run_estimation(
            run_dir,
            base,
            objective,
            run_settings,
            context={"scenario": spec_json, "defines_p": definition},
            monitor=monitor,
            evaluator=evaluator,
            provenance=stamp(definition, objective.computed_with()),
            mechanisms=MECHANISMS,
            replay_check=ReplayCheck(
                plain,
                fresh=not plain.simulator.deterministic,
                tolerance=plain.replay_tolerance,
            ),
        )
    if not monitor.started:
        err_console.print(
            f"{escape(label)}: complete already in {escape(str(out))}: read back, "
            "nothing simulated",
            highlight=False,
        )
    return run_dir


def planned(label: str, s: RunSettings) -> PlannedRun:
    """A run of ``s`` in a plan: its rollouts, and whether they are only a bound."""
    return PlannedRun(
        label,
        s.estimator.describe(),
        s.total_rollouts,
        s.estimator.budget_is_bound,
        s.rollouts_not_redrawn,
    )


def cost_meter(
    spec: ScenarioSpec,
    plan: list[PlannedRun],
    *,
    store_full: bool = False,
) -> CostMeter:
    """The cost of ``plan``, printed on stderr.

    The disk a rollout takes is estimated from the scenario's parameters
    (for rollouts stored in full apart) until the first chunk written
    measures it.
    """
    columns, base = param_layout(spec).columns, base_distribution(spec)
    return CostMeter(
        err_console,
        plan,
        estimated_row_bytes(columns, base, store_full=store_full),
        estimated_row_bytes(columns, base, store_full=True),
    )


def samples_directory(
    out: Path, spec: ScenarioSpec, *, store_full: bool = False
) -> RunDirectory:
    """A run directory of ``spec``: its units recorded, its large blocks regenerated.

    See :class:`~avrisk.pipeline.RunDirectory` for ``store_full``.
    """
    layout = param_layout(spec)
    units = {**layout.units(), "f": "s", "log_p0": "log density"}
    return RunDirectory(
        out,
        layout.columns,
        units,
        base=base_distribution(spec),
        store_full=store_full,
    )


def write_run_report(
    out: Path,
    runs: list[tuple[str, RunDirectory]],
    spec: ScenarioSpec,
    failures: int,
    reference: RunDirectory | None = None,
    simulator: ScenarioSimulator | None = None,
) -> Path:
    """The HTML report of ``runs``; failures come from the first run.

    A failure is animated from the trace recorded during the run (with the ego
    camera's RGB, depth and segmentation above the top-down view when the
    scenario has a camera); one without (a run older than recorded traces) is
    simulated again when ``simulator`` is given, else shown without animation.
    """
    failures_from = runs[0][1]
    recorded = failures_from.path / FAILURES_FILE
    traces = read_failure_traces(recorded) if recorded.is_file() else {}
    # A scenario with an ego camera shows what the ego saw beside the top-down view.
    camera = camera_from_spec(spec) if spec.camera is not None else None

    def animate(row: dict[str, Any], path: Path) -> Path | None:
        found = traces.get(int(row["seed"]))
        if found is not None:  # the title shows its min TTC; mark the vehicle hit
            trace = replace(found[1], hit=int(row.get("collision_with") or -1))
            path.parent.mkdir(parents=True, exist_ok=True)
            dt = spec.simulation.dt
            if camera is not None:
                frames = camera_frames(trace, camera)
                return animate_camera_rollout(trace, frames, spec.road, dt, path)
            return animate_rollouts([trace], spec.road, dt, path)
        if simulator is not None:
            return animate_samples(simulator, [row], path)
        return None

    then = f"the run itself is complete: free space, then 'avrisk report {out}'"
    with write_failures(out, then):
        path = write_report(
            out,
            runs,
            title=f"avrisk: {spec.name}",
            subtitle=spec.description or "",
            reference=reference,
            failures_from=failures_from,
            n_failures=failures,
            param_names=param_layout(spec).columns,
            animate=animate,
            spec=spec,
        )
    return path


def compare_runs(
    scenario: str,
    out: Path,
    tested: RunSettings,
    reference_n: int,
    failures: int,
    device: str,
    backend: tuple[Backend, int | None, str | None] = (Backend.local, None, None),
    *,
    as_json: bool = False,
) -> Path:
    """A method, naive MC at its budget and a naive reference into ``out``; report.

    The tested method's run goes to ``out/<method>``, naive Monte Carlo with
    the same number of rollouts to ``out/naive`` and the reference (if
    ``reference_n``) to ``out/reference``. ``backend``: ``--backend``,
    ``--workers`` and ``--address`` (:mod:`avrisk.cli.backends`). The plan's
    cost is printed before the first rollout; the results as tables, or with
    ``as_json`` as one JSON document on stdout (:mod:`avrisk.cli.results`).
    """
    spec = load_spec(scenario)
    check_thresholds(spec, tested)
    objective = SimulationObjective(spec, device=device, allow_import=True)
    spec_json = spec.model_dump(mode="json")
    shared = dict(
        gamma=tested.gamma, gamma_test=tested.gamma_test, batch_size=tested.batch_size
    )
    if tested.method == NAIVE_PART:
        raise CliError("compare tests a method against naive Monte Carlo: not naive")

    def naive_at(n: int) -> RunSettings:
        return settings("naive", n_final=n, seed=tested.seed + 1, **shared)

    plan = [
        (method_label(tested.method), out / tested.method, tested),
        ("naive MC, same budget", out / NAIVE_PART, naive_at(tested.total_rollouts)),
    ]
    if reference_n:
        plan.append(
            (
                "naive MC reference",
                out / REFERENCE_PART,
                settings("naive", n_final=reference_n, seed=tested.seed + 2, **shared),
            )
        )
    tested_plan = planned(plan[0][0], tested)
    naive_plan = planned(plan[1][0], plan[1][2])._replace(
        what=f"naive MC, as many rollouts as {plan[0][0]}",
        at_most=tested_plan.at_most,
    )
    rest = [planned(label, s) for label, _, s in plan[2:]]
    cost = cost_meter(spec, [tested_plan, naive_plan, *rest])
    runs: list[tuple[str, RunDirectory]] = []
    with open_evaluator(objective, *backend) as evaluator:
        for label, path, s in plan:
            if path == out / NAIVE_PART:
                # the budget the method used: subset simulation's plan is a bound
                s = naive_at(runs[0][1].summary()["estimate"]["n_evals"])
            run_dir = execute(
                label, path, objective, spec_json, s, failures, evaluator, cost=cost
            )
            runs.append((label, run_dir))
    reference = runs[2][1] if reference_n else None
    if reference is not None:
        notes = check_same_definition(
            runs[0][1].summary().get("provenance"),
            reference.summary().get("provenance"),
            "the reference run",
        )
        for note in notes:
            err_console.print(f"note: {escape(note)}", highlight=False)
    report = write_run_report(
        out, runs, spec, failures, reference, simulator=objective.simulator
    )
    show_results(
        "compare",
        runs,
        spec,
        as_json=as_json,
        ratios=ratio_rows(runs[0][1], runs[1][1], reference),
        has_reference=reference is not None,
        report=report,
    )
    return report


def comparison_parts(out: Path) -> list[tuple[str, Path]]:
    """The run directories of a comparison: the tested method first."""
    parts = (
        sorted(p.name for p in out.iterdir() if (p / "config.json").is_file())
        if out.is_dir()
        else []
    )
    rank = {NAIVE_PART: 1, REFERENCE_PART: 2}
    return [(name, out / name) for name in sorted(parts, key=lambda n: rank.get(n, 0))]
