"""Simulator throughput: avrisk's batched simulator vs highway-env, CPU and GPU.

For the bundled default scenario (6 vehicles, 6 lanes, 20-beam lidar drivers,
dt = 0.1 s, horizon 10 s), each safety measure (``--measures``: the exact box
TTC of the default scenario, and the paper's ray TTC with 360 rays) and each
batch size, report

* scenario-steps per second: simulated (rollout, step) pairs per wall second;
* real-time factor: simulated seconds per wall second (= steps/s * dt);
* rollouts per second (full rollouts, however early they stopped);
* peak memory: resident-set growth during the rollouts [MiB] (linear in B);
  on CUDA, ``torch.cuda.max_memory_allocated`` per rollout.

Rows for each mode (``--modes``: ``eager``, ``compiled``: the fullgraph step
under ``torch.compile``, compilation outside the timing), CPU threads
(``--threads``: ``1`` and/or ``all``) and device (``--devices``: ``cpu``,
``cuda`` when present). With ``cuda`` among the devices, ``--agreement`` (on
by default there) also simulates one batch on both devices and reports
whether the crashes are the same and the largest difference in ``f``
(``F_TOLERANCE``).

Side by side, in the same run, highway-env (optional: ``pip install
highway-env``) configured alike: 6 vehicles (ego + 5), 5 lanes, a 20-beam lidar
observation, 10 Hz simulation and policy, one environment stepped in a loop
(the way it is used), ego action IDLE.

Every measurement runs in its own fresh subprocess, so peak-memory figures do
not leak between batch sizes. Usage::

    .venv/bin/python benchmarks/sim_throughput.py                 # full table
    .venv/bin/python benchmarks/sim_throughput.py --batch-sizes 1,64 --quick
    .venv/bin/python benchmarks/sim_throughput.py --scenario highway_default \
        --measures min_box_ttc --modes eager,compiled --threads 1,all \
        --devices cpu,cuda --batch-sizes 1024,8192,65536   # on a GPU machine
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

#: Largest |f_cpu - f_cuda| [s] accepted by the agreement check: the driver
#: network's matrix products may round differently on a GPU (last bits), and a
#: rollout is a feedback loop; crashes must agree.
F_TOLERANCE = 1e-3


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


def _set_threads(threads: str) -> None:
    """``1`` pins torch to one thread; ``all`` keeps its default (every core)."""
    import torch

    if threads != "all":
        torch.set_num_threads(int(threads))
        torch.set_num_interop_threads(int(threads))


def _scenario_simulator(scenario: str, measure: str, device: str) -> object:
    from avrisk.assembly import ScenarioSimulator
    from avrisk.scenario import load_spec, spec_from_dict

    raw = load_spec(scenario).model_dump(mode="json")
    raw["safety"]["measure"] = measure
    return ScenarioSimulator(spec_from_dict(raw), device=device)


def _batch(sim: object, batch_size: int) -> tuple[np.ndarray, np.ndarray]:
    from avrisk.assembly import base_distribution
    from avrisk.rare.problem import chunk_rng, sample_seeds

    p0 = base_distribution(sim.spec)  # type: ignore[attr-defined]
    x = p0.sample(batch_size, chunk_rng(0, 0, 0))
    return x, sample_seeds(0, 0, np.arange(batch_size))


# -------------------------------------------------------------------- workers
def worker_avrisk(
    batch_size: int,
    scenario: str,
    measure: str,
    min_seconds: float,
    threads: str = "1",
    device: str = "cpu",
) -> dict:
    """Time rollouts of ``batch_size`` scenarios; returns a JSON-able dict."""
    import torch

    _set_threads(threads)
    from avrisk.sim.config import compile_requested
    from avrisk.tensors.allocator import keep_freed_memory

    keep_freed_memory()  # as avrisk's commands and workers do

    sim = _scenario_simulator(scenario, measure, device)
    x, seeds = _batch(sim, batch_size)
    cuda = device.startswith("cuda")

    def rollout() -> object:
        res = sim.rollout(x, seeds)  # type: ignore[attr-defined]
        if cuda:
            torch.cuda.synchronize()
        return res

    # warm up at the timed batch size: first-call costs (allocator, kernels), and
    # under AVRISK_COMPILE=1 the compilation for this shape, stay out of the timing
    start = time.perf_counter()
    rollout()
    first_s = time.perf_counter() - start
    _reset_peak()
    if cuda:
        torch.cuda.reset_peak_memory_stats()
    base_kib = _status_kib("VmRSS")
    steps = 0
    start = time.perf_counter()
    repeats = 0
    while True:
        res = rollout()
        steps += int(res.steps.sum())
        repeats += 1
        if time.perf_counter() - start >= min_seconds:
            break
    wall = time.perf_counter() - start
    peak_mib = max(0, _status_kib("VmHWM") - base_kib) / 1024
    if cuda:
        peak_mib = torch.cuda.max_memory_allocated() / 2**20
    return {
        "sim": "avrisk",
        "mode": "compiled" if compile_requested(None) else "eager",
        "device": device,
        "threads": threads if not cuda else "-",
        "measure": measure,
        "batch_size": batch_size,
        "repeats": repeats,
        "rollouts": repeats * batch_size,
        "steps": steps,
        "wall_s": wall,
        "first_call_s": first_s,
        "dt": sim.spec.simulation.dt,  # type: ignore[attr-defined]
        "peak_mib": peak_mib,
        "crash_rate": float(res.crash.float().mean()),
    }


def worker_agreement(batch_size: int, scenario: str, measure: str) -> dict:
    """One batch on CPU and on CUDA: same crashes? largest ``f`` difference?"""
    import torch

    results = {}
    for device in ("cpu", "cuda"):
        sim = _scenario_simulator(scenario, measure, device)
        x, seeds = _batch(sim, batch_size)
        res = sim.rollout(x, seeds)  # type: ignore[attr-defined]
        results[device] = (res.f.cpu(), res.crash.cpu())
    (f_cpu, crash_cpu), (f_gpu, crash_gpu) = results["cpu"], results["cuda"]
    both = torch.isfinite(f_cpu) & torch.isfinite(f_gpu)
    diff = (f_cpu - f_gpu)[both].abs().max().item() if bool(both.any()) else 0.0
    same_inf = bool((torch.isinf(f_cpu) == torch.isinf(f_gpu)).all())
    return {
        "sim": "agreement",
        "measure": measure,
        "batch_size": batch_size,
        "same_crashes": bool(torch.equal(crash_cpu, crash_gpu)),
        "same_infinite_f": same_inf,
        "max_abs_f_diff_s": diff,
        "tolerance_s": F_TOLERANCE,
        "ok": bool(torch.equal(crash_cpu, crash_gpu))
        and same_inf
        and diff <= F_TOLERANCE,
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
def _run_worker(common: list[str], worker: list[str], env: dict[str, str]) -> dict:
    cmd = [sys.executable, __file__, *common, "--worker", *worker]
    out = subprocess.run(
        cmd, check=True, capture_output=True, text=True, env=dict(os.environ, **env)
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _table(rows: list[dict]) -> str:
    lines = [
        "| simulator | device | threads | TTC measure | batch | scenario-steps/s "
        "| rollouts/s | real-time factor | peak memory [MiB] | MiB per rollout |",
        "|---|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        if "skipped" in r:
            lines.append(f"| {r['sim']} | | | | - | skipped: {r['skipped']} |||||")
            continue
        if r["sim"] == "agreement":
            continue
        sps = r["steps"] / r["wall_s"]
        rps = r.get("rollouts", r.get("episodes", 0)) / r["wall_s"]
        rtf = sps * r["dt"]
        per = r["peak_mib"] / r["batch_size"]
        sim = f"{r['sim']} ({r['mode']})" if "mode" in r else r["sim"]
        lines.append(
            f"| {sim} | {r.get('device', 'cpu')} | {r.get('threads', '1')} "
            f"| {r.get('measure', '-')} | {r['batch_size']} | {sps:,.0f} "
            f"| {rps:,.1f} | {rtf:,.0f}x | {r['peak_mib']:,.1f} | {per:.4f} |"
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
    parser.add_argument("--modes", default="eager", help="eager and/or compiled.")
    parser.add_argument("--threads", default="1", help="CPU threads: 1 and/or all.")
    parser.add_argument(
        "--devices", default="cpu", help="cpu and/or cuda (cuda rows need a GPU)."
    )
    parser.add_argument(
        "--agreement-batch", type=int, default=1024, help="Batch of the CPU-GPU check."
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
            b, measure, threads, device = rest
            result = worker_avrisk(
                int(b), args.scenario, measure, min_s, threads, device
            )
        elif kind == "agreement":
            result = worker_agreement(int(rest[0]), args.scenario, rest[1])
        else:
            _set_threads("1")
            result = worker_highway_env(min_s)
        print(json.dumps(result))
        return

    import torch

    devices = args.devices.split(",")
    if "cuda" in devices and not torch.cuda.is_available():
        print("no CUDA device: GPU rows skipped", file=sys.stderr)
        devices = [d for d in devices if d != "cuda"]
    one = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    common = ["--scenario", args.scenario, "--min-seconds", str(min_s)]
    rows = []
    for measure in args.measures.split(","):
        for device in devices:
            for mode in args.modes.split(","):
                env = {"AVRISK_COMPILE": "1" if mode == "compiled" else "0"}
                threads = args.threads.split(",") if device == "cpu" else ["all"]
                for n_threads in threads:
                    for b in (int(s) for s in args.batch_sizes.split(",")):
                        print(
                            f"avrisk {measure} {device} {mode} threads {n_threads} "
                            f"batch {b} ...",
                            file=sys.stderr,
                            flush=True,
                        )
                        worker = ["avrisk", str(b), measure, n_threads, device]
                        thread_env = one if n_threads == "1" else {}
                        rows.append(_run_worker(common, worker, env | thread_env))
        if "cuda" in devices:
            worker = ["agreement", str(args.agreement_batch), measure]
            rows.append(_run_worker(common, worker, {"AVRISK_COMPILE": "0"}))
    if not args.no_highway_env:
        print("highway-env ...", file=sys.stderr, flush=True)
        rows.append(_run_worker(common, ["highway-env"], one))

    print(
        f"\n{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}, torch {torch.__version__}; "
        f"scenario {args.scenario}; >= {min_s:g} s timed per row.\n"
    )
    print(_table(rows))
    for r in rows:
        if r["sim"] == "agreement":
            print(
                f"\nCPU vs CUDA ({r['measure']}, batch {r['batch_size']}): same "
                f"crashes {r['same_crashes']}, max |f difference| "
                f"{r['max_abs_f_diff_s']:.2e} s (tolerance {r['tolerance_s']:g} s): "
                f"{'ok' if r['ok'] else 'DISAGREE'}"
            )
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
