"""Threads under a competing load: CPU and wall time, quiet and loaded, side by side.

Runs one workload under several thread configurations, each alone ("quiet")
and beside ``--load`` CPU-bound processes (``python -c "while True: pass"``, at
the benchmark's own priority). The configurations and the two conditions are
interleaved (a round runs every configuration quiet and loaded, in an order
that turns from round to round), so that the machine's other work falls on all
of them alike. Each run is a fresh process. Workloads (``--workload``):

* ``demo`` -- ``avrisk demo`` (by default a reduced one, ``--demo-args``);
  CPU time is user + system time of the command and the processes it waited
  for (``os.wait4``), wall time the command's;
* ``rollouts`` -- ``--repeat`` rollouts of a ``--batch-size`` batch of
  ``highway_default`` over ``--steps`` steps, in a process that, like a run,
  computes within :func:`~avrisk.assembly.threads.threads_fitted_to_load`;
  CPU and wall time are those of the rollouts alone (``time.process_time``:
  every thread of the process), not of the start-up.

Configurations (environment of the process):

* ``torch`` -- ``OMP_NUM_THREADS`` = the CPU count: torch's own default, what
  avrisk did before it fitted threads to the load;
* ``fitted`` -- nothing set: avrisk's default (:mod:`avrisk.assembly.threads`);
* ``one`` -- ``OMP_NUM_THREADS=1``;
* ``passive`` -- torch's thread count with ``OMP_WAIT_POLICY=PASSIVE``.

Every run's results (the demo's ``--out`` file and each scenario run's
``estimate`` without wall times; the rollouts' ``f``) must be the same bit for
bit; the script stops otherwise. A run still going after ``--limit`` s is
stopped (its figures are then lower bounds). Prints a Markdown table of
medians and ratios. Usage::

    nice -n 19 .venv/bin/python benchmarks/thread_load.py --repeats 3
    .venv/bin/python benchmarks/thread_load.py --workload rollouts --repeats 3
    nice -n 19 .venv/bin/python benchmarks/thread_load.py --configs torch,fitted \\
        --repeats 1 --demo-args ""      # the full demo, once each
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

AVRISK = [sys.executable, "-m", "avrisk"]
SPINNER = [sys.executable, "-c", "while True: pass"]
DEMO_ARGS = "--budget 50000 --rollouts 1000 --reference 0"
#: Settings each configuration adds; every one starts from an environment
#: without these variables.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT")
CPUS = str(os.cpu_count() or 1)
CONFIGS = {
    "torch": {"OMP_NUM_THREADS": CPUS},
    "fitted": {},
    "one": {"OMP_NUM_THREADS": "1"},
    "passive": {"OMP_NUM_THREADS": CPUS, "OMP_WAIT_POLICY": "PASSIVE"},
}


def run_workload(config: str, args: argparse.Namespace, workdir: Path) -> dict:
    """One run: its CPU time [s], wall time [s], digest of its results."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env.update(CONFIGS[config])
    if args.workload == "demo":
        command = [*AVRISK, "demo", *shlex.split(args.demo_args)]
        command += ["--out", str(workdir / "estimates.json")]
        command += ["--scenario-out", str(workdir / "scenario")]
    else:
        command = [sys.executable, __file__, "--child"]
        command += [str(v) for v in (args.batch_size, args.steps, args.repeat)]
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    with (workdir / "stdout.txt").open("w") as log:
        process = subprocess.Popen(command, env=env, stdout=log, stderr=log)
        status, usage, stopped = _wait(process, start + args.limit)
    result = {
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "wall_s": time.perf_counter() - start,
        "load_before": load_before,
        "stopped": stopped,
        "digest": None,
    }
    output = (workdir / "stdout.txt").read_text()
    if stopped:
        return result
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{shlex.join(command)} failed:\n{output[-2000:]}")
    if args.workload == "demo":
        return result | {"digest": digest(workdir)}
    return (
        result | {"command_cpu_s": result["cpu_s"]} | json.loads(output.split("\n")[-2])
    )


def _wait(process: subprocess.Popen, deadline: float) -> tuple[int, object, bool]:
    """(wait status, resource usage, whether it was stopped at ``deadline``)."""
    try:
        while time.perf_counter() < deadline:
            pid, status, usage = os.wait4(process.pid, os.WNOHANG)
            if pid:
                return status, usage, False
            time.sleep(0.5)
    except BaseException:
        process.kill()
        raise
    process.kill()
    _, status, usage = os.wait4(process.pid, 0)
    return status, usage, True


def child_rollouts(batch_size: int, steps: int, repeat: int) -> None:
    """The ``rollouts`` workload; prints its CPU and wall time and digest (JSON)."""
    import numpy as np

    from avrisk.assembly import ScenarioSimulator, base_distribution
    from avrisk.assembly.threads import threads_fitted_to_load
    from avrisk.rare.problem import chunk_rng, sample_seeds
    from avrisk.scenario import load_spec

    spec = load_spec("highway_default")
    sim = spec.simulation.model_copy(update={"horizon": steps * spec.simulation.dt})
    simulator = ScenarioSimulator(spec.model_copy(update={"simulation": sim}))
    x = base_distribution(simulator.spec).sample(batch_size, chunk_rng(0, 0, 0))
    seeds = sample_seeds(0, 0, np.arange(batch_size))
    with threads_fitted_to_load() as threads:
        cpu, wall = time.process_time(), time.perf_counter()
        f = [simulator.rollout(x, seeds).f.numpy() for _ in range(repeat)]
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    f_bytes = np.concatenate(f).astype(np.float64).tobytes()
    print(
        json.dumps(
            {
                "cpu_s": cpu,
                "wall_s": wall,
                "threads": threads,
                "digest": hashlib.sha256(f_bytes).hexdigest(),
            }
        )
    )


def digest(workdir: Path) -> str:
    """SHA-256 of the demo's estimates: its --out file and each run's estimate.

    Wall times (``wall_time_s``, wherever they are) left out.
    """
    estimates = [json.loads((workdir / "estimates.json").read_text())]
    for summary in sorted((workdir / "scenario").glob("*/summary.json")):
        estimates.append(json.loads(summary.read_text())["estimate"])
    text = json.dumps(_without_wall_times(estimates), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _without_wall_times(value: object) -> object:
    if isinstance(value, dict):
        return {
            k: _without_wall_times(v) for k, v in value.items() if k != "wall_time_s"
        }
    if isinstance(value, list):
        return [_without_wall_times(v) for v in value]
    return value


class CompetingLoad:
    """``n`` CPU-bound processes while the block runs (none for n = 0)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.processes: list[subprocess.Popen] = []

    def __enter__(self) -> CompetingLoad:
        self.processes = [subprocess.Popen(SPINNER) for _ in range(self.n)]
        return self

    def __exit__(self, *exc: object) -> None:
        for process in self.processes:
            process.kill()
            process.wait()


def schedule(configs: list[str], repeats: int, load: int) -> list[tuple[int, str]]:
    """(competing processes, configuration) in run order, interleaved.

    Round r runs every configuration quiet and loaded, alternating the two,
    starting quiet in even rounds, the configurations turned by r places.
    """
    order = []
    for r in range(repeats):
        turned = configs[r % len(configs) :] + configs[: r % len(configs)]
        loads = (0, load) if r % 2 == 0 else (load, 0)
        order += [(n, c) for c in turned for n in loads]
    return order


def table(
    results: dict[tuple[int, str], list[dict]], configs: list[str], load: int
) -> str:
    """Markdown table: medians (quiet, loaded) and their ratios, per configuration."""
    med = {k: _medians(v) for k, v in results.items()}
    base = med[(0, configs[0])]
    lines = [
        "| threads | quiet CPU [s] | loaded CPU [s] | loaded / quiet CPU "
        f"| loaded CPU / {configs[0]}'s quiet "
        f"| quiet wall [s] | loaded wall [s] | quiet wall / {configs[0]}'s | runs |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in configs:
        q, ld = med[(0, c)], med[(load, c)]
        cells = [
            c,
            _figure(q, "cpu_s"),
            _figure(ld, "cpu_s"),
            _ratio(ld, q, "cpu_s"),
            _ratio(ld, base, "cpu_s"),
            _figure(q, "wall_s"),
            _figure(ld, "wall_s"),
            _ratio(q, base, "wall_s"),
            f"{len(results[(0, c)])} + {len(results[(load, c)])}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _medians(runs: list[dict]) -> dict[str, float]:
    """Median CPU and wall time, and whether any run was stopped.

    A stopped run's figures are lower bounds: the medians are then too.
    """
    return {
        "cpu_s": statistics.median(r["cpu_s"] for r in runs),
        "wall_s": statistics.median(r["wall_s"] for r in runs),
        "stopped": any(r["stopped"] for r in runs),
    }


def _figure(med: dict, key: str) -> str:
    return ("≥ " if med["stopped"] else "") + f"{med[key]:.2f}"


def _ratio(top: dict, bottom: dict, key: str) -> str:
    """top / bottom in bold; ≥ for a lower bound; ? where the bottom is one."""
    if bottom["stopped"] and top is not bottom:
        return "?"
    prefix = "≥ " if top["stopped"] and top is not bottom else ""
    return f"**{prefix}{top[key] / bottom[key]:.2f}**"


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        child_rollouts(*(int(v) for v in argv[1:]))
        return
    args = _parser().parse_args(argv)
    configs = args.configs.split(",")
    if set(configs) - set(CONFIGS):
        sys.exit(f"unknown configurations in {configs}; known: {list(CONFIGS)}")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # spinners stopped too
    results: dict[tuple[int, str], list[dict]] = {}
    runs = []
    for n, config in schedule(configs, args.repeats, args.load):
        with tempfile.TemporaryDirectory() as tmp, CompetingLoad(n):
            result = run_workload(config, args, Path(tmp))
        result.update(config=config, load=n)
        runs.append(result)
        results.setdefault((n, config), []).append(result)
        print(json.dumps(result), flush=True)
        if len({r["digest"] for r in runs} - {None}) > 1:
            sys.exit(f"{config} with load {n} gave other results than the first run")
    if args.json:
        args.json.write_text(json.dumps(runs, indent=2))
    what = (
        f"`avrisk demo {args.demo_args}`"
        if args.workload == "demo"
        else f"{args.repeat} x {args.batch_size} rollouts of {args.steps} steps"
    )
    print(
        f"\n{what}, {args.load} competing processes, {args.repeats} rounds; the "
        f"{sum(not r['stopped'] for r in runs)} runs of {len(runs)} that finished "
        f"gave the same results (>=: a run stopped after {args.limit:g} s)\n"
    )
    print(table(results, configs, args.load))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workload", choices=("demo", "rollouts"), default="demo")
    parser.add_argument("--configs", default="torch,fitted,one")
    parser.add_argument("--repeats", type=int, default=3, help="Rounds.")
    parser.add_argument("--load", type=int, default=2, help="Competing processes.")
    parser.add_argument("--demo-args", default=DEMO_ARGS)
    parser.add_argument("--batch-size", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeat", type=int, default=1, help="Rollouts per run.")
    parser.add_argument("--limit", type=float, default=3600, help="Stop a run [s].")
    parser.add_argument("--json", type=Path, help="Write every run's figures here.")
    return parser


if __name__ == "__main__":
    main()
