"""The external ego's cost: round trips and rollouts per second against in-process.

On ``highway_idm`` (10 s horizon, 100 steps, 20-beam lidar), the reference
controller (:class:`avrisk.agents.external.server.AccController`) drives the
ego three ways at batch sizes 1, 64 and 1,024: in process, through the Python
reference server (``avrisk serve-ego``, another process) and, with ``--cpp``,
through the C++ one. A round trip is one request and its reply (``hello``,
``reset``, one ``step`` per time step); "wire only" sends one batch's
observation again and again (no simulation: the protocol's own cost). Every
server binds 127.0.0.1.

Usage (the figures in BENCHMARKS.md)::

    make -C examples/ego_server_cpp BUILD=/tmp/ego_cpp
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/external_ego.py \\
        --cpp /tmp/ego_cpp/ego_server
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time

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


def measure(sim, batch, min_seconds):
    base = base_distribution(sim.spec)
    rng = np.random.default_rng(0)
    rollouts = steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < min_seconds:
        result = sim.rollout(base.sample(batch, rng), rng.integers(0, 2**62, batch))
        assert (result.status.numpy() == 0).all()
        rollouts += batch
        steps += int(result.steps.max()) + 2  # + hello and reset
    wall = time.perf_counter() - start
    return rollouts / wall, steps / wall


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cpp", help="the built C++ reference server")
    parser.add_argument("--batches", default="1,64,1024")
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    cli = "from avrisk.cli import main; main()"
    servers = {"python": [sys.executable, "-c", cli, "serve-ego", "--address"]}
    if args.cpp:
        servers["c++"] = [args.cpp]
    print("| ego | batch | rollouts/s | round trips/s | wire-only round trips/s |")
    print("|---|---:|---:|---:|---:|")
    for batch in (int(b) for b in args.batches.split(",")):
        local = simulator(LocalEgo(AccController()))
        rate, _ = measure(local, batch, args.seconds)
        print(f"| in process | {batch} | {rate:,.1f} | - | - |", flush=True)
        for name, command in servers.items():
            address = free_address()
            proc = subprocess.Popen([*command, address], stdout=subprocess.PIPE)
            try:
                proc.stdout.readline()  # bound
                ego = get_policy("external", {"address": address}, n_vehicles=6,
                                 device="cpu")  # fmt: skip
                sim = simulator(ego)
                rate, trips = measure(sim, batch, args.seconds)
                wire = wire_only(ego, sim, batch, args.seconds)
                print(f"| {name} server | {batch} | {rate:,.1f} | {trips:,.0f} | "
                      f"{wire:,.0f} |", flush=True)  # fmt: skip
            finally:
                proc.kill()
                proc.wait()


if __name__ == "__main__":
    main()
