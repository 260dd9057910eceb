"""``avrisk simulate`` and ``avrisk replay``: naive rollouts from P0, and animations.

``simulate`` draws ``X ~ P0`` (seeded, batch-size independent), simulates every
rollout and writes one Parquet row per rollout, in the samples-table format of
a run (:func:`avrisk.pipeline.store.samples_table`)::

    phase, stage, iteration, chunk, sample_id, seed, veh0.s, ..., veh5.speed,
    log_p0, log_p_proposal, log_weight, weight, f, crash, offroad, reversing,
    steps, status, collision_with, contact

The resolved scenario spec travels in the file's schema metadata, so
``replay`` can re-simulate any row from the file alone; ``replay`` takes a
run directory (or its ``samples.parquet``) too, whose spec is its
``config.json``. A spec read back from a file never makes avrisk import code:
one that names user code by import path must be given again (``--scenario``).

The simulator (torch) is imported where it runs, not by this module: ``--help``
starts without it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import pyarrow as pa
import typer
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

import avrisk
from avrisk.cli.common import (
    CliError,
    Device,
    check_output_file,
    err_console,
    out_console,
    user_errors,
    write_failures,
)
from avrisk.cli.readback import (
    check_columns,
    check_rows,
    parse_json,
    read_config,
    read_schema,
    read_table,
    stored_params,
)
from avrisk.cli.tables import add_columns, compact_table
from avrisk.extras import MissingExtraError
from avrisk.pipeline.files import write_parquet_atomic
from avrisk.pipeline.regenerate import RegenerationError
from avrisk.pipeline.store import CONFIG_FILE, SAMPLES_FILE, RunDirectory, samples_table
from avrisk.rare import RareEventProblem, StageBatch, run_stage
from avrisk.rare.problem import FINAL_STAGE
from avrisk.registry import ComponentError
from avrisk.scenario import (
    ScenarioSpec,
    ScenarioSpecError,
    load_spec,
    spec_from_dict,
)

#: Thresholds on the minimum TTC [s] counted in the summary.
SUMMARY_GAMMAS: tuple[float, ...] = (0.1, 0.2, 0.3)

#: Parquet schema-metadata keys.
META_SCENARIO = b"avrisk.scenario"
META_RUN = b"avrisk.run"

_RESULT_COLUMNS = ("log_p0", "f", "crash", "offroad", "reversing", "steps")


# ----------------------------------------------------------------------- core
@dataclass(frozen=True)
class SimulationRun:
    """The rows of one ``simulate`` run, as a Parquet-ready Arrow table.

    Attributes
    ----------
    table : pyarrow.Table
        One row per rollout, ``n`` rows, ordered by ``sample_id``.
    wall_s : float
        Wall-clock time of the simulation [s].
    """

    table: pa.Table
    wall_s: float


def simulate_rollouts(
    spec: ScenarioSpec,
    n: int,
    *,
    seed: int = 0,
    batch_size: int = 1024,
    device: str = "cpu",
    on_batch: Callable[[int], None] | None = None,
) -> SimulationRun:
    """Sample ``n`` scenarios from ``P0`` and simulate them.

    The samples are the final stage of a naive Monte Carlo run with the same
    seed (:func:`avrisk.rare.run_stage`): sample ``i`` and its rollout seed
    depend only on ``seed`` and ``i``, never on ``batch_size``, and
    ``avrisk run --method naive --seed S`` simulates exactly these rollouts.

    Parameters
    ----------
    spec : ScenarioSpec
    n : int
        Number of rollouts, ``>= 1``.
    seed : int, default=0
        Run seed, ``>= 0``.
    batch_size : int, default=1024
        Rollouts simulated together (memory grows linearly with it).
    device : str, default="cpu"
        Torch device of the simulator.
    on_batch : callable or None
        Called with the number of rollouts finished after each chunk.

    Returns
    -------
    SimulationRun
    """
    from avrisk.assembly import SimulationObjective, base_distribution

    objective = SimulationObjective(spec, device=device)
    p0 = base_distribution(spec)
    problem = RareEventProblem(p0, objective, gamma=0.0, batch_size=batch_size)
    batches: list[StageBatch] = []

    def record(batch: StageBatch) -> None:
        batches.append(batch)
        if on_batch is not None:
            on_batch(len(batch.values))

    start_time = time.perf_counter()
    run_stage(problem, p0, n, seed=seed, stage=FINAL_STAGE, on_batch=record)
    wall_s = time.perf_counter() - start_time

    run_meta = {
        "avrisk_version": avrisk.__version__,
        "command": "simulate",
        "run_seed": seed,
        "n": n,
        "device": device,
        "scenario": spec.name,
    }
    layout = objective.layout
    units = {**layout.units(), "f": "s", "log_p0": "log density"}
    table = pa.concat_tables(
        samples_table(b, layout.columns, units)
        for b in sorted(batches, key=lambda b: b.chunk)
    )
    table = table.replace_schema_metadata(
        {
            META_SCENARIO: json.dumps(spec.model_dump(mode="json")).encode(),
            META_RUN: json.dumps(run_meta).encode(),
        }
    )
    return SimulationRun(table=table, wall_s=wall_s)


def spec_from_parquet(path: Path) -> ScenarioSpec:
    """The scenario of a samples table: stored in it, or in its run's config.json.

    Raises
    ------
    CliError
        If neither holds a (valid) scenario.
    """
    meta = read_schema(path).metadata or {}
    if META_SCENARIO in meta:
        stored = parse_json(meta[META_SCENARIO], f"{path} (its stored scenario)")
        return spec_from_dict(stored, source=f"{path} (stored)")
    config = path.parent / CONFIG_FILE
    if config.is_file():
        stored = read_config(path.parent)["scenario"]
        return spec_from_dict(stored, source=str(config))
    raise CliError(
        f"{path} carries no scenario (neither written by 'avrisk simulate' nor in "
        "a run directory); pass --scenario to name it"
    )


# ------------------------------------------------------------------------ CLI
#: Where ``simulate`` and ``replay`` write without ``--out`` (``runs/`` is made).
DEFAULT_ROLLOUTS = Path("runs/rollouts.parquet")
DEFAULT_GIF = Path("runs/replay.gif")


def _out_path(out: Path | None, default: Path, suffixes: Sequence[str]) -> Path:
    """``--out``, or ``default`` (its folder made); checked to be writable."""
    if out is None:
        out = default
        out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() not in suffixes:
        raise CliError(
            f"--out {out}: expected a file ending in {' or '.join(suffixes)}"
        )
    check_output_file(out)
    return out


def _summary_table(table: pa.Table, wall_s: float) -> Table:
    n = table.num_rows
    f = table.column("f").to_numpy()
    summary = compact_table(
        f"{n} rollouts in {wall_s:.1f} s ({n / max(wall_s, 1e-9):.0f}/s)"
    )
    add_columns(summary, ["event", "count", "fraction"], text=["event"])
    rows = [(f"min TTC <= {g:g} s", int(np.sum(f <= g))) for g in SUMMARY_GAMMAS]
    rows += [
        (k, int(np.sum(table.column(k).to_numpy())))
        for k in ("crash", "offroad", "reversing")
    ]
    for name, k in rows:
        # Zero hits is not p = 0: show the 95% upper bound (rule of three).
        frac = f"{k / n:.3g}" if k else f"< {3.0 / n:.2g} (95%)"
        summary.add_row(name, str(k), frac)
    return summary


def simulate(
    scenario: Annotated[
        str, typer.Argument(help="Scenario YAML file, or a bundled name.")
    ] = "highway_default",
    n: Annotated[int, typer.Option("--n", min=1, help="Number of rollouts.")] = 1000,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Run seed.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help=f"Parquet file to write (one row per rollout) [default: "
            f"{DEFAULT_ROLLOUTS}].",
        ),
    ] = None,
    batch_size: Annotated[
        int, typer.Option("--batch-size", min=1, help="Rollouts simulated together.")
    ] = 1024,
    device: Device = "cpu",
    threads: Annotated[
        int | None, typer.Option(min=1, help="CPU threads for torch (default: all).")
    ] = None,
) -> None:
    """Sample scenarios from P0, simulate them, write one Parquet row per rollout."""
    with user_errors(ScenarioSpecError, ComponentError, MissingExtraError):
        spec = load_spec(scenario)
        out = _out_path(out, DEFAULT_ROLLOUTS, (".parquet", ".pq"))
        if threads is not None:
            import torch

            torch.set_num_threads(threads)
        progress = Progress(
            TextColumn("[bold]simulate[/] {task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err_console,
            transient=False,
        )
        with progress:
            task = progress.add_task(spec.name, total=n)
            run = simulate_rollouts(
                spec,
                n,
                seed=seed,
                batch_size=batch_size,
                device=device,
                on_batch=lambda k: progress.advance(task, k),
            )
        try:
            write_parquet_atomic(run.table, out)
        except OSError as exc:
            raise CliError(f"--out {out}: cannot write: {exc}") from None
    out_console.print(_summary_table(run.table, run.wall_s))
    out_console.print(f"wrote {out}", highlight=False)


def _parse_rows(rows: str, n_rows: int) -> list[int]:
    try:
        picked = [int(r) for r in rows.split(",") if r.strip()]
    except ValueError:
        raise CliError(f"--rows {rows!r}: expected row numbers like 0,5,12") from None
    if not picked:
        raise CliError("--rows: give at least one row number, like 0,5")
    bad = [r for r in picked if not 0 <= r < n_rows]
    if bad:
        raise CliError(f"--rows: {bad} out of range; the file has rows 0..{n_rows - 1}")
    return picked


def replay(
    file: Annotated[
        Path,
        typer.Argument(
            help="Parquet file written by 'avrisk simulate', or a run directory "
            "(or its samples.parquet): its scenario is read from the file or the "
            "run's config.json, as data (no code imported)."
        ),
    ],
    rows: Annotated[
        str | None, typer.Option(help="Comma-separated row numbers, e.g. 0,5,12.")
    ] = None,
    worst: Annotated[
        int | None,
        typer.Option(min=1, help="Instead of --rows: the K rows of lowest f."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help=f"GIF file to write [default: {DEFAULT_GIF}].")
    ] = None,
    scenario: Annotated[
        str | None,
        typer.Option(
            help="Scenario to use instead of the one stored with the samples: "
            "needed only for one that names user code by import path."
        ),
    ] = None,
    fps: Annotated[int, typer.Option(min=1, max=50, help="Frames per second.")] = 10,
    view_length: Annotated[
        float,
        typer.Option(min=10.0, help="Length of road shown around the ego, in metres."),
    ] = 120.0,
    frame_png: Annotated[
        Path | None, typer.Option(help="Also save the frame of lowest TTC as a PNG.")
    ] = None,
) -> None:
    """Re-simulate chosen rows of a samples table and write a top-down GIF."""
    from avrisk.assembly import (
        ScenarioSimulator,
        base_distribution,
        param_layout,
        resimulate,
    )
    from avrisk.report.animate import animate_rollouts, save_frame_png

    with user_errors(
        ScenarioSpecError, ComponentError, MissingExtraError, RegenerationError
    ):
        if file.is_dir() and not (file / SAMPLES_FILE).is_file():
            parts = sorted(p.parent.name for p in file.glob(f"*/{SAMPLES_FILE}"))
            hint = f"; a comparison: give one of its runs, e.g. {file / parts[0]}"
            raise CliError(f"{file}: holds no {SAMPLES_FILE}" + (hint if parts else ""))
        if file.is_dir():
            file = file / SAMPLES_FILE
        if not file.is_file():
            raise CliError(f"{file}: no such file")
        out = _out_path(out, DEFAULT_GIF, (".gif",))
        if frame_png is not None:
            check_output_file(frame_png, "--frame-png")
        table = read_table(file)
        spec = load_spec(scenario) if scenario else spec_from_parquet(file)
        layout = param_layout(spec)
        if (rows is None) == (worst is None):
            raise CliError("give exactly one of --rows i,j,... or --worst K")
        stored = stored_params(table.schema, layout.columns)
        with_f = ("f",) if "f" in table.column_names or worst is not None else ()
        check_columns(table.schema, file, (*stored, *with_f), ("seed",))
        if rows is not None:
            picked = _parse_rows(rows, table.num_rows)
        else:
            order = np.argsort(table.column("f").to_numpy(), kind="stable")
            picked = [int(i) for i in order[:worst]]
        sub = table.take(picked)
        if len(stored) < len(layout.columns):  # a run's table, xi left out
            base = base_distribution(spec)
            run_dir = RunDirectory(file.parent, layout.columns, base=base)
            sub = run_dir.samples(rows=picked)
        missing = [c for c in (*layout.columns, "seed") if c not in sub.column_names]
        if missing:
            raise CliError(
                f"{file}: lacks column(s) {missing[:4]} needed to replay scenario "
                f"{spec.name!r}"
            )
        x = np.stack([sub.column(c).to_numpy() for c in layout.columns], axis=1)
        check_rows(spec, layout.columns, x, picked, file)
        seeds = sub.column("seed").to_numpy()
        sim = ScenarioSimulator(spec, allow_import=scenario is not None)
        result, traces = resimulate(sim, x, seeds, [f"row {r}" for r in picked])
        if "f" in sub.column_names:
            stored = sub.column("f").to_numpy()
            again = result.f.cpu().numpy().astype(np.float64)
            if not np.allclose(stored, again, rtol=1e-5, atol=1e-6, equal_nan=True):
                err_console.print(
                    "[yellow]warning:[/] re-simulated min TTC differs from the file "
                    f"(stored {stored.tolist()}, now {again.tolist()}); was the "
                    "simulator or scenario changed?"
                )
        with write_failures(out.parent, "free space and rerun the command"):
            animate_rollouts(
                traces,
                spec.road,
                spec.simulation.dt,
                out,
                fps=fps,
                view_length=view_length,
            )
            if frame_png is not None:
                save_frame_png(
                    traces,
                    spec.road,
                    spec.simulation.dt,
                    frame_png,
                    view_length=view_length,
                )
    for r, tr in zip(picked, traces, strict=True):
        out_console.print(
            f"row {r}: min TTC {tr.min_ttc:.3g} s"
            + (", crash" if tr.crashed else "")
            + f", {tr.n_frames} frames",
            highlight=False,
        )
    out_console.print(
        f"wrote {out}" + (f" and {frame_png}" if frame_png else ""), highlight=False
    )
