"""Runs of a scenario: estimate, compare with naive MC, rebuild the report.

What ``avrisk run``, ``compare``, ``report`` and ``demo`` do, as library
calls that print nothing (progress goes to a callback,
:mod:`avrisk.api.events`) and return an :class:`EstimationResult`. Every
function here works for any registered estimator
(:func:`avrisk.rare.estimator_names`): labels, progress and report sections
come from the estimator itself.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from avrisk.api.backends import DEFAULT_BACKEND, open_evaluator
from avrisk.api.document import Runs, answer, ratio_rows, result_document
from avrisk.api.errors import UserError, write_failures
from avrisk.api.events import Note, Plan, PlannedRun, Progress, ignore, run_events
from avrisk.api.readback import check_recorded, check_samples, read_config
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
from avrisk.extras import MissingExtraError
from avrisk.pipeline import RunDirectory, RunDirectoryError, RunSettings, run_estimation
from avrisk.pipeline.provenance import (
    ProvenanceMismatchError,
    check_same_definition,
    stamp,
)
from avrisk.pipeline.regenerate import RegenerationError
from avrisk.pipeline.repeatability import NotRepeatableError, ReplayCheck
from avrisk.pipeline.store import SAMPLES_FILE, estimated_row_bytes
from avrisk.rare import InvalidOutputError, Product
from avrisk.rare.estimator import TooManyFailuresError, estimator_class
from avrisk.rare.evaluation import Evaluator
from avrisk.rare.parallel import WorkerError
from avrisk.rare.splitting import SplittingError
from avrisk.registry import ComponentError
from avrisk.report.animate import animate_rollouts, animate_samples
from avrisk.report.answer import Headline
from avrisk.report.camera_video import animate_camera_rollout
from avrisk.report.html import write_report
from avrisk.scenario import (
    ScenarioSpec,
    ScenarioSpecError,
    load_spec,
    spec_from_dict,
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
#: Sub-directories of a comparison besides the tested method's own.
NAIVE_PART, REFERENCE_PART = "naive", "reference"


def method_label(method: str) -> str:
    """The human name of a registered estimator (``"cross-entropy"``)."""
    return estimator_class(method).label


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
    """A run of ``s`` in a plan: its rollouts, and whether they are only a bound."""
    return PlannedRun(
        label,
        s.estimator.describe(),
        s.total_rollouts,
        s.estimator.budget_is_bound,
        s.rollouts_not_redrawn,
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


def samples_directory(
    out: Path,
    spec: ScenarioSpec,
    *,
    store_full: bool = False,
    base: Product | None = None,
) -> RunDirectory:
    """A run directory of ``spec``: its units recorded, its large blocks regenerated.

    See :class:`~avrisk.pipeline.RunDirectory` for ``store_full``; ``base``
    is the ``P0`` its blocks are drawn again from (default the scenario's
    with the shipped drivers' prior).
    """
    layout = param_layout(spec)
    units = {**layout.units(), "f": "s", "log_p0": "log density"}
    return RunDirectory(
        out,
        layout.columns,
        units,
        base=base_distribution(spec) if base is None else base,
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


Scenario = str | Path | ScenarioSpec | dict[str, Any]
#: Where rollouts are simulated: a registered backend's name, its workers and
#: its Ray address
#: (:func:`avrisk.api.backends.open_evaluator`).
BackendChoice = tuple[str, int | None, str | None]
IN_PROCESS: BackendChoice = (DEFAULT_BACKEND, None, None)


@dataclass(frozen=True)
class EstimationResult:
    """Complete runs of one scenario and their report: what the API returns.

    Attributes
    ----------
    command : str
        ``"run"``, ``"compare"`` or ``"report"``: what made it.
    runs : list of (label, RunDirectory)
        The runs, the one under test first (then naive MC at its budget and
        the reference, for a comparison).
    spec : ScenarioSpec
        Their scenario.
    report : Path or None
        The HTML report written.
    ratios : list of dict or None
        A comparison's rows per threshold
        (:func:`~avrisk.api.document.ratio_rows`).
    has_reference : bool
        Whether a comparison has a naive reference run.
    """

    command: str
    runs: Runs
    spec: ScenarioSpec
    report: Path | None = None
    ratios: list[dict[str, Any]] | None = None
    has_reference: bool = False

    @property
    def estimate(self) -> dict[str, Any]:
        """The estimate of the run under test, as its ``summary.json`` holds it."""
        return self.runs[0][1].summary()["estimate"]

    @property
    def p(self) -> float:
        """``P0(f(X) <= gamma)`` at the run's main threshold."""
        return self.estimate["p"]

    @property
    def ci(self) -> tuple[float, float]:
        """The 95% interval of :attr:`p`."""
        low, high = self.estimate["ci"]
        return low, high

    @property
    def by_gamma(self) -> dict[float, float]:
        """``p`` at every threshold [s] of the run under test."""
        return {g["gamma"]: g["p"] for g in self.estimate["by_gamma"]}

    @property
    def path(self) -> Path:
        """The run directory of the run under test."""
        return self.runs[0][1].path

    def answer(self) -> Headline:
        """The answer, as the report and the command give it."""
        return answer(self.runs, self.spec)

    def document(self) -> dict[str, Any]:
        """Every figure, as ``--json`` prints it (schema ``avrisk.result/1``)."""
        return result_document(
            self.command, self.runs, self.spec, ratios=self.ratios, report=self.report
        )

    def __str__(self) -> str:
        return self.answer().sentence()


def scenario_spec(scenario: Scenario) -> ScenarioSpec:
    """A scenario given as a bundled name, a YAML path, a spec or its data."""
    if isinstance(scenario, ScenarioSpec):
        return scenario
    if isinstance(scenario, dict):
        return spec_from_dict(scenario)
    return load_spec(scenario)


def estimate_spec(
    spec: ScenarioSpec,
    run_settings: RunSettings,
    out: Path,
    *,
    failures: int = 6,
    store_full: bool = False,
    device: str = "cpu",
    backend: BackendChoice = IN_PROCESS,
    progress: Progress = ignore,
) -> EstimationResult:
    """Run (or resume, or read back) an estimation of ``spec`` into ``out``; report.

    The plan goes to ``progress`` before the first rollout, then the run's
    events (:func:`execute`); the report (``out/report.html``) animates the
    ``failures`` most likely dangerous rollouts. ``backend``: where the
    rollouts are simulated (:data:`BackendChoice`).
    """
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
    shared = dict(
        gamma=tested.gamma, gamma_test=tested.gamma_test, batch_size=tested.batch_size
    )
    if tested.method == NAIVE_PART:
        raise UserError("compare tests a method against naive Monte Carlo: not naive")

    def naive_at(n: int) -> RunSettings:
        return settings("naive", n_final=n, seed=tested.seed + 1, **shared)

    runs_plan = [
        (method_label(tested.method), out / tested.method, tested),
        ("naive MC, same budget", out / NAIVE_PART, naive_at(tested.total_rollouts)),
    ]
    if reference_n:
        runs_plan.append(
            (
                "naive MC reference",
                out / REFERENCE_PART,
                settings("naive", n_final=reference_n, seed=tested.seed + 2, **shared),
            )
        )
    tested_plan = planned(runs_plan[0][0], tested)
    naive_plan = planned(runs_plan[1][0], runs_plan[1][2])._replace(
        what=f"naive MC, as many rollouts as {runs_plan[0][0]}",
        at_most=tested_plan.at_most,
    )
    rest = [planned(label, s) for label, _, s in runs_plan[2:]]
    progress(plan(spec, [tested_plan, naive_plan, *rest]))
    runs: Runs = []
    with open_evaluator(objective, *backend) as evaluator:
        for label, path, s in runs_plan:
            if path == out / NAIVE_PART:
                # the budget the method used: subset simulation's plan is a bound
                s = naive_at(runs[0][1].summary()["estimate"]["n_evals"])
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


def comparison_parts(out: Path) -> list[tuple[str, Path]]:
    """The run directories of a comparison: the tested method first."""
    parts = (
        sorted(p.name for p in out.iterdir() if (p / "config.json").is_file())
        if out.is_dir()
        else []
    )
    rank = {NAIVE_PART: 1, REFERENCE_PART: 2}
    return [(name, out / name) for name in sorted(parts, key=lambda n: rank.get(n, 0))]


def rebuild_report(
    run_dir: Path,
    failures: int = 6,
    scenario: Scenario | None = None,
    device: str = "cpu",
) -> EstimationResult:
    """The report of a finished run or comparison in ``run_dir``, written again.

    Failures are animated from the traces recorded during the run; one
    without is simulated again, for which a scenario that names user code by
    import path must be given again (``scenario``: the run directory alone
    never makes avrisk import code). Every record is checked before use.
    """
    single = (run_dir / "config.json").is_file()
    parts = [] if single else comparison_parts(run_dir)
    if not single and not parts:
        raise UserError(f"{run_dir} holds no avrisk run (no config.json)")
    dirs = [("run", run_dir)] if single else parts
    for _, path in dirs:
        check_recorded(path)
    config = read_config(dirs[0][1])
    spec = spec_from_dict(config["scenario"], source=f"{dirs[0][1]}/config.json")
    simulator = None
    if scenario is not None:
        given = scenario_spec(scenario)
        if given.model_dump(mode="json") != config["scenario"]:
            raise UserError(
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
            raise UserError(f"{path} is not finished; rerun its command to resume it")
        check_samples(directory.path / SAMPLES_FILE, layout.columns)
        label = method_label(directory.config()["settings"]["method"])
        runs.append((label if single else f"{label} ({name})", directory))
        by_name[name] = directory
    ref_dir = by_name.get(REFERENCE_PART)
    naive = by_name.get(NAIVE_PART)
    path = write_run_report(run_dir, runs, spec, failures, ref_dir, simulator=simulator)
    return EstimationResult(
        "report",
        runs,
        spec,
        path,
        None if naive is None else ratio_rows(runs[0][1], naive, ref_dir),
        ref_dir is not None,
    )
