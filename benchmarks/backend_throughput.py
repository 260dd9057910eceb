"""Throughput of ``avrisk run`` on each backend: in-process, local workers, Ray.

Runs ``avrisk run SCENARIO --method naive --n-final N --failures 0`` once per
configuration, each in a fresh process (and, for Ray, a fresh local cluster on
127.0.0.1), and reports side by side

* rollouts/s: the run's own figure (``summary.json``: rollouts over the time the
  run waited for results; workers' start-up, simulator build included);
* command [s]: wall time of the whole command (imports, Ray start, report);
* ratio: rollouts/s against the in-process run of the same table.

All configurations give the same estimate (checked: ``p`` must agree). Usage::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/backend_throughput.py
    .venv/bin/python benchmarks/backend_throughput.py --n 8192 --configs in-process,ray2
"""

from __future__ import annotations

import argparse
import json
import os
import platform
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
    args = parser.parse_args()
    names = [c.strip() for c in args.configs.split(",")]
    unknown = sorted(set(names) - set(CONFIGS))
    if unknown:
        parser.error(f"unknown configurations {unknown}; known: {list(CONFIGS)}")
    print(
        f"# {args.scenario}, naive, {args.n} rollouts; {platform.processor()} "
        f"{os.cpu_count()} CPUs; OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}"
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, name in enumerate(names):
            rows.append(
                (name, measure(args.scenario, args.n, CONFIGS[name], Path(tmp, str(i))))
            )
    if len({row["p"] for _, row in rows}) != 1:
        sys.exit(f"the backends disagree on p: {[(n, r['p']) for n, r in rows]}")
    base = rows[0][1]["rollouts_per_second"]
    header = f"| configuration | options | rollouts/s | ratio to {rows[0][0]} |"
    print(header + " command [s] |")
    print("|---|---|---:|---:|---:|")
    for name, row in rows:
        rate = row["rollouts_per_second"]
        options = " ".join(CONFIGS[name]) or "(none)"
        print(
            f"| {name} | `{options}` | {rate:.0f} | {rate / base:.2f} "
            f"| {row['command_s']:.1f} |"
        )


if __name__ == "__main__":
    main()
