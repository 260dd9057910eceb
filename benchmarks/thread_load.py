"""Threads under a competing load: CPU and wall time of the demo, side by side.

Runs one ``avrisk demo`` workload (by default a reduced one: ``--budget 50000
--rollouts 1000 --reference 0``) under several thread configurations, each
alone ("quiet") and beside ``--load`` CPU-bound processes (``python -c "while
True: pass"``, at the benchmark's own priority). The configurations and the two
conditions are interleaved (a round runs every configuration quiet and loaded,
in an order that turns from round to round), so that the machine's other work
falls on all of them alike. Each run is a fresh command; its CPU time is user +
system time of the command and the processes it waited for (``os.wait4``).

Configurations (environment of the command):

* ``torch`` -- ``OMP_NUM_THREADS`` = the CPU count: torch's own default, what
  avrisk did before it fitted threads to the load;
* ``fitted`` -- nothing set: avrisk's default (:mod:`avrisk.tensors.threads`);
* ``one`` -- ``OMP_NUM_THREADS=1``;
* ``passive`` -- torch's thread count with ``OMP_WAIT_POLICY=PASSIVE``.

Every run's estimates (the demo's ``--out`` file and each scenario run's
``estimate``, wall times left out) must be the same bit for bit; the script
stops otherwise. Prints a Markdown table of medians and ratios. Usage::

    nice -n 19 .venv/bin/python benchmarks/thread_load.py --repeats 3
    nice -n 19 .venv/bin/python benchmarks/thread_load.py --configs torch,fitted \\
        --repeats 1 --demo-args ""      # the full demo, once each
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
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


def run_demo(config: str, demo_args: list[str], workdir: Path, limit_s: float) -> dict:
    """One demo command: its CPU time [s] (children included), wall time [s], digest.

    A command still running after ``limit_s`` is stopped: its figures are then
    lower bounds (``stopped``) and it has no digest.
    """
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env.update(CONFIGS[config])
    out = workdir / "estimates.json"
    command = [
        *AVRISK,
        "demo",
        *demo_args,
        "--out",
        str(out),
        "--scenario-out",
        str(workdir / "scenario"),
    ]
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    with (workdir / "stdout.txt").open("w") as log:
        process = subprocess.Popen(command, env=env, stdout=log, stderr=log)
        status, usage, stopped = _wait(process, start + limit_s)
    wall = time.perf_counter() - start
    if not stopped and os.waitstatus_to_exitcode(status) != 0:
        log_text = (workdir / "stdout.txt").read_text()[-2000:]
        raise RuntimeError(f"{shlex.join(command)} failed:\n{log_text}")
    return {
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "wall_s": wall,
        "load_before": load_before,
        "stopped": stopped,
        "digest": None if stopped else digest(workdir),
    }


def _wait(process: subprocess.Popen, deadline: float) -> tuple[int, object, bool]:
    """(wait status, resource usage, whether it was stopped at ``deadline``)."""
    while time.perf_counter() < deadline:
        pid, status, usage = os.wait4(process.pid, os.WNOHANG)
        if pid:
            return status, usage, False
        time.sleep(0.5)
    process.kill()
    _, status, usage = os.wait4(process.pid, 0)
    return status, usage, True


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
    return ("≥ " if med["stopped"] else "") + f"{med[key]:.1f}"


def _ratio(top: dict, bottom: dict, key: str) -> str:
    """top / bottom in bold; ≥ for a lower bound; ? where the bottom is one."""
    if bottom["stopped"] and top is not bottom:
        return "?"
    prefix = "≥ " if top["stopped"] and top is not bottom else ""
    return f"**{prefix}{top[key] / bottom[key]:.2f}**"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", default="torch,fitted,one")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--load", type=int, default=2, help="Competing processes.")
    parser.add_argument("--demo-args", default=DEMO_ARGS)
    parser.add_argument(
        "--limit", type=float, default=3600, help="Stop a run after this many s."
    )
    parser.add_argument("--json", type=Path, help="Write every run's figures here.")
    args = parser.parse_args(argv)
    configs = args.configs.split(",")
    unknown = set(configs) - set(CONFIGS)
    if unknown:
        parser.error(
            f"unknown configurations {sorted(unknown)}; known: {list(CONFIGS)}"
        )
    results: dict[tuple[int, str], list[dict]] = {}
    runs = []
    for n, config in schedule(configs, args.repeats, args.load):
        with tempfile.TemporaryDirectory() as tmp, CompetingLoad(n):
            result = run_demo(
                config, shlex.split(args.demo_args), Path(tmp), args.limit
            )
        result.update(config=config, load=n)
        runs.append(result)
        results.setdefault((n, config), []).append(result)
        print(json.dumps(result), flush=True)
        digests = {r["digest"] for r in runs} - {None}
        if len(digests) > 1:
            sys.exit(f"{config} with load {n} gave other estimates than the first run")
    if args.json:
        args.json.write_text(json.dumps(runs, indent=2))
    print(
        f"\n`avrisk demo {args.demo_args}`, {args.load} competing processes, "
        f"{args.repeats} rounds; the {sum(not r['stopped'] for r in runs)} runs of "
        f"{len(runs)} that finished gave the same estimates (>=: a run stopped "
        f"after {args.limit:g} s, its figures lower bounds)\n"
    )
    print(table(results, configs, args.load))


if __name__ == "__main__":
    main()
