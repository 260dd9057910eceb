"""The HTML report of finished runs: written after a run, rebuilt from its folder.

A report animates the most likely failures from the traces recorded during
the run, with the ego camera's view where the scenario has a camera
(:func:`write_run_report`); :func:`rebuild_report` writes it again from a run
or comparison directory alone, every record checked before use.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from avrisk.api.document import ratio_rows
from avrisk.api.errors import UserError, write_failures
from avrisk.api.readback import check_recorded, check_samples, read_config
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
    ScenarioSimulator,
    camera_frames,
    camera_from_spec,
    param_layout,
    read_failure_traces,
)
from avrisk.pipeline import RunDirectory
from avrisk.pipeline.layout import SAMPLES_FILE
from avrisk.report.animate import animate_rollouts, animate_samples
from avrisk.report.camera_video import animate_camera_rollout
from avrisk.report.html import write_report
from avrisk.scenario import ScenarioSpec, spec_from_dict

__all__ = ["comparison_parts", "rebuild_report", "write_run_report"]


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
