"""The external ego's cost: round trips and rollouts per second against in-process.

On ``highway_idm`` (10 s horizon, 100 steps, 20-beam lidar), the reference
controller (:class:`avrisk.agents.external.server.AccController`) drives the
ego three ways at batch sizes 1, 64 and 1,024: in process, through the Python
reference server (``avrisk serve-ego``, another process) and, with ``--cpp``,
through the C++ one. A round trip is one request and its reply (``hello``,
``reset``, one ``step`` per time step); "wire only" sends one batch's
observation again and again (no simulation: the protocol's own cost). Every
server binds 127.0.0.1.

On a loaded machine single rates mean little, so the configurations of a
batch size run side by side: ``--repeats`` rounds, each running every
configuration once on the same rollouts (``--rollouts`` of them: the same
``X`` and seeds), in an order that rotates from round to round; wire only
runs for ``--seconds``. Each run gives rollouts per second of wall time
and per second of CPU time (this process's and the server's, from
``/proc``): on a loaded machine the wall rate depends on the scheduler (two
processes that take turns get more of a contended core than one that never
sleeps), the CPU rate much less. The summary gives medians over the rounds,
and the median of each round's ratio of a server's rate to the in-process
rate of the same round (its range in brackets). The load average (1 min) is
printed before and after.

Usage (the figures in BENCHMARKS.md; ``taskset`` keeps the client and the
servers, which take turns, on one core)::

    make -C examples/ego_server_cpp BUILD=/tmp/ego_cpp
    OMP_NUM_THREADS=1 taskset -c 1 .venv/bin/python benchmarks/external_ego.py \\
        --cpp /tmp/ego_cpp/ego_server --repeats 3
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from avrisk.agents import as_ego_actor, get_policy
from avrisk.agents.external.server import AccController, LocalEgo
from avrisk.assembly import ScenarioSimulator, base_distribution, initial_state
from avrisk.scenario import ScenarioParams, load_spec


def free_address() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def simulator(ego):
    sim = ScenarioSimulator(load_spec("highway_idm"))
    sim.ego_policy = as_ego_actor(ego, sim.spec.n_vehicles)
    return sim


def cpu_seconds(pids):
    """CPU time [s] used so far by this process and the processes ``pids``."""
    total = time.process_time()
    for pid in pids:  # /proc/PID/stat: utime and stime, fields 14 and 15
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def measure(sim, batch, n_rollouts, pids=()):
    """Rollouts/s, rollouts per CPU second and round trips/s of ``n_rollouts``.

    The same rollouts every time, ``batch`` at a time; CPU time is this
    process's and the server's (``pids``).
    """
    base = base_distribution(sim.spec)
    rng = np.random.default_rng(0)
    n, steps = max(batch, n_rollouts), 0
    start, cpu = time.perf_counter(), cpu_seconds(pids)
    for _ in range(n // batch):
        result = sim.rollout(base.sample(batch, rng), rng.integers(0, 2**62, batch))
        assert (result.status.numpy() == 0).all()
        steps += int(result.steps.max()) + 2  # + hello and reset
    wall, cpu = time.perf_counter() - start, cpu_seconds(pids) - cpu
    return n / wall, n / cpu, steps / wall


def wire_only(ego, sim, batch, min_seconds):
    """Step round trips/s of the protocol alone: one observation sent again."""
    base = base_distribution(sim.spec)
    rng = np.random.default_rng(0)
    state = initial_state(
        ScenarioParams.from_flat(base.sample(batch, rng), sim.layout), sim.spec
    )
    obs = sim.simulator.observe(state, torch.zeros(batch, dtype=torch.int64))
    episode = ego.init(obs, None)
    trips, start = 0, time.perf_counter()
    while time.perf_counter() - start < min_seconds:
        ego.act(obs, episode, None)
        trips += 1
    assert episode.fault is None, episode.fault
    return trips / (time.perf_counter() - start)


def in_process(batch, n_rollouts):
    """Rollouts/s and per CPU second of the in-process ego; no round trips."""
    rate, per_cpu, _ = measure(simulator(LocalEgo(AccController())), batch, n_rollouts)
    return rate, per_cpu, math.nan, math.nan


def through(address, pids, batch, n_rollouts, seconds):
    """Rollouts/s and per CPU second, round trips/s, wire only, via a server."""
    ego = get_policy("external", {"address": address}, n_vehicles=6, device="cpu")
    sim = simulator(ego)
    rate, per_cpu, trips = measure(sim, batch, n_rollouts, pids)
    return rate, per_cpu, trips, wire_only(ego, sim, batch, seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cpp", help="the built C++ reference server")
    parser.add_argument("--batches", default="1,64,1024")
    parser.add_argument(
        "--rollouts", default="8,128,1024", help="rollouts per run, per batch size"
    )
    parser.add_argument("--seconds", type=float, default=3.0, help="of wire only")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cli = "from avrisk.cli import main; main()"
    servers = {"python server": [sys.executable, "-c", cli, "serve-ego", "--address"]}
    if args.cpp:
        servers["c++ server"] = [args.cpp]
    procs, addresses, pids = [], {}, {}
    print(f"load average before: {os.getloadavg()[0]:.2f}", flush=True)
    try:
        for name, command in servers.items():
            addresses[name] = free_address()
            procs.append(
                subprocess.Popen([*command, addresses[name]], stdout=subprocess.PIPE)
            )
            procs[-1].stdout.readline()  # bound
            pids[name] = (procs[-1].pid,)
        names = ["in process", *servers]
        rows = []
        work = zip(args.batches.split(","), args.rollouts.split(","), strict=True)
        for batch, n_rollouts in ((int(b), int(n)) for b, n in work):
            for r in range(args.repeats):
                k = r % len(names)
                for name in names[k:] + names[:k]:  # rotate the order each round
                    if name == "in process":
                        figures = in_process(batch, n_rollouts)
                    else:
                        figures = through(
                            addresses[name], pids[name], batch, n_rollouts, args.seconds
                        )
                    rows.append((batch, r, name, *figures))
                    print(f"round {r} batch {batch} {name}: {figures[0]:.2f} "
                          f"rollouts/s, {figures[1]:.2f} per CPU s",
                          flush=True)  # fmt: skip
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(summary(rows, names))


def summary(rows, names):
    """Markdown: medians over the rounds, and paired ratios to in-process."""
    lines = [
        "| batch | ego | rollouts/s | ratio | rollouts per CPU s | ratio "
        "| round trips/s | wire-only round trips/s |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for batch in sorted({row[0] for row in rows}):
        mine = [row for row in rows if row[0] == batch]
        base = {row[1]: row for row in mine if row[2] == "in process"}
        for name in names:
            runs = [row for row in mine if row[2] == name]
            cells = []
            for i in (3, 4):  # a rate, then its median ratio [range] to in-process
                ratios = [row[i] / base[row[1]][i] for row in runs]
                cells.append(f"{np.median([row[i] for row in runs]):,.2f}")
                cells.append(
                    "1"
                    if name == "in process"
                    else f"{np.median(ratios):.2f} "
                    f"[{min(ratios):.2f}, {max(ratios):.2f}]"
                )
            for i in (5, 6):
                v = np.median([row[i] for row in runs])
                cells.append("-" if math.isnan(v) else f"{v:,.0f}")
            lines.append(f"| {batch} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
