"""Runs of a scenario: estimate, or compare with naive MC, and report.

What ``avrisk run``, ``compare``, ``report`` and ``demo`` do, as library
calls that print nothing (progress goes to a callback,
:mod:`avrisk.api.events`) and return an :class:`EstimationResult`. Every
function here works for any registered estimator
(:func:`avrisk.rare.estimator_names`): labels, progress and report sections
come from the estimator itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from avrisk.api.backends import DEFAULT_BACKEND, open_evaluator
from avrisk.api.document import Runs, ratio_rows
from avrisk.api.errors import UserError, write_failures
from avrisk.api.events import Note, Plan, PlannedRun, Progress, ignore, run_events
from avrisk.api.readback import check_recorded
from avrisk.api.reports import write_run_report
from avrisk.api.result import (
    NAIVE_PART,
    REFERENCE_PART,
    EstimationResult,
    Scenario,
    method_label,
    samples_directory,
    scenario_spec,
)
from avrisk.assembly import (
    FAILURES_FILE,
    MECHANISMS,
    FailureRecorder,
    SimulationObjective,
    base_distribution,
    param_layout,
    scenario_typicality,
)
from avrisk.extras import MissingExtraError
from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.pipeline.provenance import (
    ProvenanceMismatchError,
    check_same_definition,
    stamp,
)
from avrisk.pipeline.regenerate import RegenerationError
from avrisk.pipeline.repeatability import NotRepeatableError, ReplayCheck
from avrisk.pipeline.sizing import estimated_row_bytes
from avrisk.rare import InvalidOutputError
from avrisk.rare.estimation_context import TooManyFailuresError
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.parallel import WorkerError
from avrisk.rare.splitting_levels import SplittingError
from avrisk.registry import ComponentError
from avrisk.scenario import (
    ScenarioSpec,
    ScenarioSpecError,
)

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


def settings(method: str, **kwargs: Any) -> RunSettings:
    """Validated run settings, or a one-line UserError."""
    try:
        return RunSettings(method, **kwargs)
    except (KeyError, ValueError) as err:
        raise UserError(str(err).strip('"')) from None


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
        raise UserError(
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
    progress: Progress = ignore,
) -> RunDirectory:
    """Run (or resume, or read back) one estimation into ``out``.

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
    ``progress`` gets the run's events (:func:`avrisk.api.events.run_events`);
    a run that was complete already has no
    :class:`~avrisk.api.events.RunStarted`.
    """
    check_recorded(out)  # a damaged config or summary: one line, not a traceback
    base = objective.base_distribution()
    run_dir = samples_directory(
        out, objective.simulator.spec, store_full=store_full, base=base
    )
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
    with write_failures(out, resume), run_events(label, out, progress) as monitor:
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
    return run_dir


def planned(label: str, s: RunSettings) -> PlannedRun:
    """A run of ``s`` in a plan: its rollouts, a bound or not, and its growth."""
    growth = s.most_rollouts - s.total_rollouts  # levels: stored in full
    return PlannedRun(
        label,
        s.estimator.describe(),
        s.total_rollouts,
        s.estimator.budget_is_bound,
        max(s.rollouts_not_redrawn - growth, 0),
        s.most_rollouts if growth > 0 else 0,
    )


def plan(
    spec: ScenarioSpec,
    runs: list[PlannedRun],
    *,
    store_full: bool = False,
) -> Plan:
    """The plan of ``runs``, with the disk a rollout will take.

    The disk is estimated from the scenario's parameters (for rollouts
    stored in full apart) until the first chunk written measures it.
    """
    columns, base = param_layout(spec).columns, base_distribution(spec)
    return Plan(
        tuple(runs),
        estimated_row_bytes(columns, base, store_full=store_full),
        estimated_row_bytes(columns, base, store_full=True),
    )


#: Where rollouts are simulated: a registered backend's name, its workers and
#: its Ray address
#: (:func:`avrisk.api.backends.open_evaluator`).
BackendChoice = tuple[str, int | None, str | None]
IN_PROCESS: BackendChoice = (DEFAULT_BACKEND, None, None)


def estimate_spec(
    scenario: Scenario,
    run_settings: RunSettings,
    out: Path,
    *,
    failures: int = 6,
    store_full: bool = False,
    device: str = "cpu",
    backend: BackendChoice = IN_PROCESS,
    progress: Progress = ignore,
) -> EstimationResult:
    """Run (or resume, or read back) an estimation of ``scenario`` into ``out``.

    ``scenario``: a bundled name, a YAML path, a spec or its data (the result's
    ``spec`` is the one loaded). The plan goes to ``progress`` before the first
    rollout, then the run's events (:func:`execute`); the report
    (``out/report.html``) animates the ``failures`` most likely dangerous
    rollouts. ``backend``: where the rollouts are simulated
    (:data:`BackendChoice`).
    """
    spec = scenario_spec(scenario)
    check_thresholds(spec, run_settings)
    objective = SimulationObjective(spec, device=device, allow_import=True)
    label = method_label(run_settings.method)
    progress(plan(spec, [planned(label, run_settings)], store_full=store_full))
    with open_evaluator(objective, *backend) as evaluator:
        run_dir = execute(
            label,
            out,
            objective,
            spec.model_dump(mode="json"),
            run_settings,
            failures,
            evaluator,
            store_full=store_full,
            progress=progress,
        )
    runs = [(label, run_dir)]
    report = write_run_report(out, runs, spec, failures, simulator=objective.simulator)
    return EstimationResult("run", runs, spec, report)


def compare_runs(
    scenario: Scenario,
    out: Path,
    tested: RunSettings,
    reference_n: int,
    failures: int,
    device: str,
    backend: BackendChoice = IN_PROCESS,
    *,
    progress: Progress = ignore,
) -> EstimationResult:
    """A method, naive MC at its budget and a naive reference into ``out``; report.

    The tested method's run goes to ``out/<method>``, naive Monte Carlo with
    the same number of rollouts to ``out/naive`` and the reference (if
    ``reference_n``) to ``out/reference``. ``backend``: where the rollouts
    are simulated (:data:`BackendChoice`). The plan goes to ``progress``
    before the first rollout, then each run's events, and a
    :class:`~avrisk.api.events.Note` where the reference was made otherwise.
    """
    spec = scenario_spec(scenario)
    check_thresholds(spec, tested)
    objective = SimulationObjective(spec, device=device, allow_import=True)
    spec_json = spec.model_dump(mode="json")
    if tested.method == NAIVE_PART:
        raise UserError("compare tests a method against naive Monte Carlo: not naive")
    runs_plan = _comparison_runs(out, tested, reference_n)
    progress(_comparison_plan(spec, runs_plan))
    runs: Runs = []
    with open_evaluator(objective, *backend) as evaluator:
        for label, path, s in runs_plan:
            if path == out / NAIVE_PART:
                # the budget the method used: subset simulation's plan is a bound
                s = _naive(tested, runs[0][1].summary()["estimate"]["n_evals"], 1)
            run_dir = execute(
                label,
                path,
                objective,
                spec_json,
                s,
                failures,
                evaluator,
                progress=progress,
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
            progress(Note(note))
    report = write_run_report(
        out, runs, spec, failures, reference, simulator=objective.simulator
    )
    return EstimationResult(
        "compare",
        runs,
        spec,
        report,
        ratio_rows(runs[0][1], runs[1][1], reference),
        reference is not None,
    )


def _naive(tested: RunSettings, n: int, seed_offset: int) -> RunSettings:
    """Naive MC of ``n`` rollouts at ``tested``'s thresholds, its seed + offset."""
    return settings(
        "naive",
        n_final=n,
        seed=tested.seed + seed_offset,
        gamma=tested.gamma,
        gamma_test=tested.gamma_test,
        batch_size=tested.batch_size,
    )


def _comparison_runs(
    out: Path, tested: RunSettings, reference_n: int
) -> list[tuple[str, Path, RunSettings]]:
    """``(label, folder, settings)`` of a comparison's runs, the tested one first.

    Naive MC's budget here is the tested method's plan; :func:`compare_runs`
    gives it the rollouts the method used once it has run.
    """
    runs = [
        (method_label(tested.method), out / tested.method, tested),
        (
            "naive MC, same budget",
            out / NAIVE_PART,
            _naive(tested, tested.total_rollouts, 1),
        ),
    ]
    if reference_n:
        runs.append(
            (
                "naive MC reference",
                out / REFERENCE_PART,
                _naive(tested, reference_n, 2),
            )
        )
    return runs


def _comparison_plan(
    spec: ScenarioSpec, runs: list[tuple[str, Path, RunSettings]]
) -> Plan:
    """The plan of a comparison: naive MC as many rollouts as the tested method."""
    tested = planned(runs[0][0], runs[0][2])
    naive = planned(runs[1][0], runs[1][2])._replace(
        what=f"naive MC, as many rollouts as {runs[0][0]}",
        at_most=tested.at_most,
    )
    rest = [planned(label, s) for label, _, s in runs[2:]]
    return plan(spec, [tested, naive, *rest])
