"""Throughput of ``avrisk run`` on each backend: in-process, local workers, Ray.

Runs ``avrisk run SCENARIO --method naive --n-final N --failures 0`` once per
configuration, each in a fresh process (and, for Ray, a fresh local cluster on
127.0.0.1), and reports side by side

* rollouts/s: the run's own figure (``summary.json``: rollouts over the time the
  run waited for results; workers' start-up, simulator build included);
* command [s]: wall time of the whole command (imports, Ray start, report);
* ratio: rollouts/s against the first configuration of the table.

With ``--rounds R`` every configuration runs ``R`` times, the configurations in
turn (round 1: all of them, round 2: all again...), so that a drift of the
machine's load touches them alike; the table gives each one's median and range.
All runs give the same estimate (checked: ``p`` must agree). Usage::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/backend_throughput.py
    .venv/bin/python benchmarks/backend_throughput.py --n 8192 --configs in-process,ray2
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/backend_throughput.py \
        --scenario highway_default --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Configuration name -> extra options of ``avrisk run``.
CONFIGS = {
    "in-process": (),
    "workers1": ("--workers", "1"),
    "workers2": ("--workers", "2"),
    "ray1": ("--backend", "ray", "--workers", "1"),
    "ray2": ("--backend", "ray", "--workers", "2"),
}
COMMAND = "import sys; from avrisk.cli import main; sys.argv[0] = 'avrisk'; main()"


def measure(scenario: str, n: int, options: tuple[str, ...], out: Path) -> dict:
    """One ``avrisk run`` in a fresh process: its summary's timing and ``p``."""
    args = [sys.executable, "-c", COMMAND, "run", scenario, "--out", str(out)]
    args += ["--method", "naive", "--n-final", str(n), "--failures", "0", *options]
    start = time.perf_counter()
    subprocess.run(args, check=True, capture_output=True)
    wall = time.perf_counter() - start
    summary = json.loads((out / "summary.json").read_text())
    return {
        "rollouts_per_second": summary["timing"]["rollouts_per_second"],
        "command_s": wall,
        "p": summary["estimate"]["by_gamma"][0]["p"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="highway_idm")
    parser.add_argument("--n", type=int, default=4 * 8192, help="rollouts per run")
    parser.add_argument(
        "--configs",
        default=",".join(CONFIGS),
        help=f"comma-separated, of: {', '.join(CONFIGS)}",
    )
    parser.add_argument(
        "--rounds", type=int, default=1, help="runs of every configuration, in turn"
    )
    args = parser.parse_args()
    names = [c.strip() for c in args.configs.split(",")]
    unknown = sorted(set(names) - set(CONFIGS))
    if unknown:
        parser.error(f"unknown configurations {unknown}; known: {list(CONFIGS)}")
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1; got {args.rounds}")
    print(
        f"# {args.scenario}, naive, {args.n} rollouts, {args.rounds} round(s); "
        f"{platform.processor()} {os.cpu_count()} CPUs; "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}"
    )
    runs: dict[str, list[dict]] = {name: [] for name in names}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for name in names:
                out = Path(tmp, f"{name}-{r}")
                row = measure(args.scenario, args.n, CONFIGS[name], out)
                runs[name].append(row)
                print(
                    f"# round {r + 1} {name}: {row['rollouts_per_second']:.0f} "
                    f"rollouts/s, command {row['command_s']:.1f} s",
                    flush=True,
                )
    estimates = {row["p"] for rows in runs.values() for row in rows}
    if len(estimates) != 1:
        sys.exit(f"the runs disagree on p: {sorted(estimates)}")

    def spread(name: str, key: str, fmt: str) -> str:
        values = [row[key] for row in runs[name]]
        text = format(statistics.median(values), fmt)
        if len(values) > 1:
            text += f" ({min(values):{fmt}}-{max(values):{fmt}})"
        return text

    base = statistics.median(row["rollouts_per_second"] for row in runs[names[0]])
    print(f"| configuration | options | rollouts/s | ratio to {names[0]} ", end="")
    print("| command [s] |")
    print("|---|---|---:|---:|---:|")
    for name in names:
        rate = statistics.median(row["rollouts_per_second"] for row in runs[name])
        options = " ".join(CONFIGS[name]) or "(none)"
        print(
            f"| {name} | `{options}` | {spread(name, 'rollouts_per_second', '.0f')} "
            f"| {rate / base:.2f} | {spread(name, 'command_s', '.1f')} |"
        )


if __name__ == "__main__":
    main()
