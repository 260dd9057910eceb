"""Simulator throughput: avrisk's batched simulator vs highway-env, one CPU thread.

For the bundled default scenario (6 vehicles, 6 lanes, 20-beam lidar drivers,
dt = 0.1 s, horizon 10 s), each safety measure (``--measures``: the exact box
TTC of the default scenario, and the paper's ray TTC with 360 rays) and each
batch size, report

* scenario-steps per second: simulated (rollout, step) pairs per wall second;
* real-time factor: simulated seconds per wall second (= steps/s * dt);
* peak memory: resident-set growth during the rollouts [MiB] (linear in B).

Side by side, in the same run, highway-env (optional: ``pip install
highway-env``) configured alike: 6 vehicles (ego + 5), 5 lanes, a 20-beam lidar
observation, 10 Hz simulation and policy, one environment stepped in a loop
(the way it is used), ego action IDLE.

Every measurement runs in its own fresh subprocess pinned to one thread, so
peak-memory figures do not leak between batch sizes. Usage::

    .venv/bin/python benchmarks/sim_throughput.py                 # full table
    .venv/bin/python benchmarks/sim_throughput.py --batch-sizes 1,64 --quick

With ``AVRISK_COMPILE=1`` in the environment the avrisk rows use
``torch.compile`` (the ``mode`` column says which).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _status_kib(key: str) -> int:
    """A ``VmRSS``/``VmHWM`` line of /proc/self/status [KiB] (0 if unavailable)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def _reset_peak() -> None:
    """Reset the process's peak-RSS counter (Linux ``clear_refs`` 5)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def _set_one_thread() -> None:
    import torch

    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)


# -------------------------------------------------------------------- workers
def worker_avrisk(
    batch_size: int, scenario: str, measure: str, min_seconds: float
) -> dict:
    """Time rollouts of ``batch_size`` scenarios; returns a JSON-able dict."""
    _set_one_thread()
    from avrisk.assembly import ScenarioSimulator, base_distribution
    from avrisk.rare.problem import chunk_rng, sample_seeds
    from avrisk.scenario import load_spec, spec_from_dict
    from avrisk.sim.simulator import compile_requested

    raw = load_spec(scenario).model_dump(mode="json")
    raw["safety"]["measure"] = measure
    spec = spec_from_dict(raw)
    sim = ScenarioSimulator(spec)
    p0 = base_distribution(spec)
    x = p0.sample(batch_size, chunk_rng(0, 0, 0))
    seeds = sample_seeds(0, 0, np.arange(batch_size))
    # warm up at the timed batch size: first-call costs (allocator, kernels), and
    # under AVRISK_COMPILE=1 the compilation for this shape, stay out of the timing
    sim.rollout(x, seeds)
    _reset_peak()
    base_kib = _status_kib("VmRSS")
    steps = 0
    start = time.perf_counter()
    repeats = 0
    while True:
        res = sim.rollout(x, seeds)
        steps += int(res.steps.sum())
        repeats += 1
        if time.perf_counter() - start >= min_seconds:
            break
    wall = time.perf_counter() - start
    return {
        "sim": "avrisk",
        "mode": "compiled" if compile_requested(None) else "eager",
        "measure": measure,
        "batch_size": batch_size,
        "repeats": repeats,
        "steps": steps,
        "wall_s": wall,
        "dt": spec.simulation.dt,
        "peak_mib": max(0, _status_kib("VmHWM") - base_kib) / 1024,
        "crash_rate": float(res.crash.float().mean()),
    }


def worker_highway_env(min_seconds: float) -> dict:
    """Step one highway-env environment configured like the default scenario."""
    try:
        import gymnasium
        import highway_env  # noqa: F401
    except ImportError as exc:
        return {"sim": "highway-env", "skipped": f"not installed ({exc.name})"}
    config = {
        "lanes_count": 5,
        "vehicles_count": 5,
        "controlled_vehicles": 1,
        "observation": {"type": "LidarObservation", "cells": 20, "maximum_range": 50},
        "action": {"type": "DiscreteMetaAction"},
        "simulation_frequency": 10,
        "policy_frequency": 10,
        "duration": 10,  # [s]
        "offscreen_rendering": True,
    }
    env = gymnasium.make("highway-v0", config=config, render_mode=None)
    idle = env.unwrapped.action_type.actions_indexes["IDLE"]
    env.reset(seed=0)
    _reset_peak()
    base_kib = _status_kib("VmRSS")
    steps = episodes = 0
    step_wall = 0.0
    start = time.perf_counter()
    while time.perf_counter() - start < min_seconds:
        env.reset(seed=episodes)
        episodes += 1
        done = False
        while not done:
            t0 = time.perf_counter()
            _, _, terminated, truncated, _ = env.step(idle)
            step_wall += time.perf_counter() - t0
            steps += 1
            done = terminated or truncated
    wall = time.perf_counter() - start
    n_vehicles = len(env.unwrapped.road.vehicles)
    env.close()
    return {
        "sim": "highway-env",
        "batch_size": 1,
        "episodes": episodes,
        "steps": steps,
        "wall_s": wall,
        "step_wall_s": step_wall,
        "dt": 1.0 / config["policy_frequency"],
        "peak_mib": max(0, _status_kib("VmHWM") - base_kib) / 1024,
        "n_vehicles": n_vehicles,
    }


# ----------------------------------------------------------------------- main
def _run_worker(common: list[str], worker: list[str]) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, __file__, *common, "--worker", *worker]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _table(rows: list[dict]) -> str:
    lines = [
        "| simulator | TTC measure | batch | scenario-steps/s | real-time factor "
        "| peak memory [MiB] | MiB per rollout |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['sim']} | | - | skipped: {r['skipped']} | | | |")
            continue
        sps = r["steps"] / r["wall_s"]
        rtf = sps * r["dt"]
        per = r["peak_mib"] / r["batch_size"]
        sim = f"{r['sim']} ({r['mode']})" if "mode" in r else r["sim"]
        lines.append(
            f"| {sim} | {r.get('measure', '-')} | {r['batch_size']} | {sps:,.0f} "
            f"| {rtf:,.0f}x | "
            f"{r['peak_mib']:,.1f} | {per:.3f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch-sizes", default="1,64,1024,8192")
    parser.add_argument("--scenario", default="highway_idm")
    parser.add_argument(
        "--measures",
        default="min_box_ttc,min_ttc",
        help="Safety measures to time, comma-separated (registered names).",
    )
    parser.add_argument(
        "--min-seconds", type=float, default=3.0, help="Least timed wall time per row."
    )
    parser.add_argument(
        "--quick", action="store_true", help="0.5 s per row (smoke test)."
    )
    parser.add_argument("--no-highway-env", action="store_true")
    parser.add_argument("--json", type=Path, help="Also write the raw rows here.")
    parser.add_argument("--worker", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    min_s = min(0.5, args.min_seconds) if args.quick else args.min_seconds

    if args.worker is not None:
        kind, *rest = args.worker
        if kind == "avrisk":
            result = worker_avrisk(int(rest[0]), args.scenario, rest[1], min_s)
        else:
            result = worker_highway_env(min_s)
        print(json.dumps(result))
        return

    common = ["--scenario", args.scenario, "--min-seconds", str(min_s)]
    rows = []
    for measure in args.measures.split(","):
        for b in (int(s) for s in args.batch_sizes.split(",")):
            print(f"avrisk {measure} batch {b} ...", file=sys.stderr, flush=True)
            rows.append(_run_worker(common, ["avrisk", str(b), measure]))
    if not args.no_highway_env:
        print("highway-env ...", file=sys.stderr, flush=True)
        rows.append(_run_worker(common, ["highway-env"]))
    import torch

    print(
        f"\nOne CPU thread; {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, torch {torch.__version__}; "
        f"scenario {args.scenario}; >= {min_s:g} s timed per row.\n"
    )
    print(_table(rows))
    hw = [r for r in rows if r["sim"] == "highway-env" and "skipped" not in r]
    if hw:
        print(
            f"\nhighway-env: {hw[0]['n_vehicles']} vehicles on the road, "
            f"{hw[0]['episodes']} episodes; env.step alone "
            f"{hw[0]['steps'] / hw[0]['step_wall_s']:,.0f} steps/s."
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
