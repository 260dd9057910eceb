"""Naive rollouts from ``P0`` as a table, and chosen rollouts simulated again.

:func:`simulate_rollouts` draws ``X ~ P0`` (seeded, batch-size independent),
simulates every rollout and returns one row per rollout, in the samples-table
format of a run (:func:`avrisk.pipeline.samples.samples_table`)::

    phase, stage, iteration, chunk, sample_id, seed, veh0.s, ..., veh5.speed,
    log_p0, log_p_proposal, log_weight, weight, f, crash, offroad, reversing,
    steps, status, collision_with, contact

The resolved scenario spec travels in the table's schema metadata, so
:func:`replay_rollouts` can simulate any row again from the file alone; it
takes a run's ``samples.parquet`` too, whose spec is its ``config.json``. A
spec read back from a file never makes avrisk import code: one that names
user code by import path must be given again (``scenario``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from avrisk.api.errors import UserError, write_failures
from avrisk.api.readback import (
    check_columns,
    check_rows,
    parse_json,
    read_config,
    read_schema,
    read_table,
    stored_params,
)
from avrisk.api.result import Scenario, scenario_spec
from avrisk.assembly import (
    RolloutTrace,
    ScenarioSimulator,
    SimulationObjective,
    base_distribution,
    param_layout,
    resimulate,
)
from avrisk.pipeline.files import write_parquet_atomic
from avrisk.pipeline.layout import CONFIG_FILE
from avrisk.pipeline.samples import samples_table
from avrisk.pipeline.store import RunDirectory
from avrisk.rare import RareEventProblem, StageBatch, run_stage
from avrisk.rare.problem import FINAL_STAGE
from avrisk.report.animate import animate_rollouts, save_frame_png
from avrisk.scenario import ScenarioSpec, load_spec, spec_from_dict
from avrisk.version import __version__

#: Parquet schema-metadata keys.
META_SCENARIO = b"avrisk.scenario"
META_RUN = b"avrisk.run"


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
        "avrisk_version": __version__,
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


def write_rollouts(
    scenario: Scenario,
    n: int,
    out: Path,
    *,
    seed: int = 0,
    batch_size: int = 1024,
    device: str = "cpu",
    threads: int | None = None,
    on_start: Callable[[str], None] | None = None,
    on_batch: Callable[[int], None] | None = None,
) -> SimulationRun:
    """:func:`simulate_rollouts` of ``scenario``, its table written to ``out``.

    What ``avrisk simulate`` does: ``threads`` sets torch's CPU threads first
    (None: leaves them); ``on_start`` is called with the scenario's name before
    the first rollout; the Parquet file is replaced atomically.

    Raises
    ------
    UserError
        If ``out`` cannot be written.
    """
    spec = scenario_spec(scenario)
    if threads is not None:
        import torch

        torch.set_num_threads(threads)
    if on_start is not None:
        on_start(spec.name)
    run = simulate_rollouts(
        spec, n, seed=seed, batch_size=batch_size, device=device, on_batch=on_batch
    )
    try:
        write_parquet_atomic(run.table, out)
    except OSError as exc:
        raise UserError(f"--out {out}: cannot write: {exc}") from None
    return run


def spec_from_parquet(path: Path) -> ScenarioSpec:
    """The scenario of a samples table: stored in it, or in its run's config.json.

    Raises
    ------
    UserError
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
    raise UserError(
        f"{path} carries no scenario (neither written by 'avrisk simulate' nor in "
        "a run directory); pass --scenario to name it"
    )


def parse_rows(rows: str, n_rows: int) -> list[int]:
    """The row numbers ``"0,5,12"`` names, each checked to be one of ``n_rows``."""
    try:
        picked = [int(r) for r in rows.split(",") if r.strip()]
    except ValueError:
        raise UserError(f"--rows {rows!r}: expected row numbers like 0,5,12") from None
    if not picked:
        raise UserError("--rows: give at least one row number, like 0,5")
    bad = [r for r in picked if not 0 <= r < n_rows]
    if bad:
        raise UserError(
            f"--rows: {bad} out of range; the file has rows 0..{n_rows - 1}"
        )
    return picked


@dataclass(frozen=True)
class Replay:
    """Rows of a samples table simulated again, and their animation.

    Attributes
    ----------
    rows : list of int
        The rows replayed, in the animation's order.
    traces : list of RolloutTrace
        Their trajectories, one per row.
    stored_f, again_f : list of float or None
        The minimum TTC [s] the table holds and the one simulated now, where
        they differ (a simulator or scenario changed); None where they agree.
    """

    rows: list[int]
    traces: list[RolloutTrace]
    stored_f: list[float] | None = None
    again_f: list[float] | None = None


def replay_rollouts(
    file: Path,
    out: Path,
    *,
    rows: str | None = None,
    worst: int | None = None,
    scenario: str | None = None,
    fps: int = 10,
    view_length: float = 120.0,
    frame_png: Path | None = None,
) -> Replay:
    """Simulate rows of the samples table ``file`` again; a top-down GIF in ``out``.

    ``rows`` (``"0,5,12"``) or ``worst`` (the K rows of lowest ``f``) picks
    them; ``scenario`` replaces the one stored with the samples (needed only
    for one that names user code by import path). ``view_length``: road
    shown around the ego [m]; ``frame_png``: also the frame of lowest TTC.
    """
    table = read_table(file)
    spec = load_spec(scenario) if scenario else spec_from_parquet(file)
    layout = param_layout(spec)
    if (rows is None) == (worst is None):
        raise UserError("give exactly one of --rows i,j,... or --worst K")
    stored = stored_params(table.schema, layout.columns)
    with_f = ("f",) if "f" in table.column_names or worst is not None else ()
    check_columns(table.schema, file, (*stored, *with_f), ("seed",))
    if rows is not None:
        picked = parse_rows(rows, table.num_rows)
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
        raise UserError(
            f"{file}: lacks column(s) {missing[:4]} needed to replay scenario "
            f"{spec.name!r}"
        )
    x = np.stack([sub.column(c).to_numpy() for c in layout.columns], axis=1)
    check_rows(spec, layout.columns, x, picked, file)
    seeds = sub.column("seed").to_numpy()
    sim = ScenarioSimulator(spec, allow_import=scenario is not None)
    result, traces = resimulate(sim, x, seeds, [f"row {r}" for r in picked])
    replay = Replay(picked, traces)
    if "f" in sub.column_names:
        stored = sub.column("f").to_numpy()
        again = result.f.cpu().numpy().astype(np.float64)
        if not np.allclose(stored, again, rtol=1e-5, atol=1e-6, equal_nan=True):
            replay = Replay(picked, traces, stored.tolist(), again.tolist())
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
    return replay
