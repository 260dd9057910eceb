"""Tensor operations per simulation step, by name, and where the time goes.

For each bundled scenario, one batch of rollouts on one CPU thread:

* **ops per step**: ATen operations dispatched per simulated step
  (:class:`avrisk.tensors.opcount.OpCounter`), the difference between a
  rollout of ``T + 10`` and one of ``T`` steps divided by 10 (so set-up work is
  not counted), with the top operations by count;
* **host syncs per step**: ``_local_scalar_dense`` calls (``.item()``,
  ``bool(tensor)``) and ``nonzero``, which wait for the device on a GPU;
* **self time**: ``torch.profiler`` self CPU time by operation, top entries.

Usage::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/step_profile.py --batch-size 2048
    OMP_NUM_THREADS=1 AVRISK_COMPILE=1 .venv/bin/python benchmarks/step_profile.py

``--json`` writes the figures (``tests/sim/test_step.py`` bounds the op counts).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile

from avrisk.assembly import ScenarioSimulator, base_distribution
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import load_spec
from avrisk.tensors.opcount import OpCounter

SCENARIOS = ("highway_idm", "highway_default")
#: ATen operations that make the host wait for the device.
SYNC_OPS = ("_local_scalar_dense", "nonzero", "item")


def _simulator(scenario: str, n_steps: int) -> ScenarioSimulator:
    spec = load_spec(scenario)
    sim = spec.simulation
    horizon = n_steps * sim.dt
    return ScenarioSimulator(
        spec.model_copy(
            update={"simulation": sim.model_copy(update={"horizon": horizon})}
        )
    )


def profile_scenario(scenario: str, batch_size: int, n_steps: int, top: int) -> dict:
    """Op counts and profile of ``scenario`` (see the module docstring)."""
    sims = [_simulator(scenario, n_steps), _simulator(scenario, n_steps + 10)]
    p0 = base_distribution(sims[0].spec)
    x = p0.sample(batch_size, chunk_rng(0, 0, 0))
    seeds = sample_seeds(0, 0, np.arange(batch_size))
    counted = []
    for sim in sims:
        sim.rollout(x, seeds)  # warm-up (and compilation, if switched on)
        with OpCounter() as ops:
            res = sim.rollout(x, seeds)
        if int(res.steps.min()) < sim.n_steps:
            raise RuntimeError("a rollout stopped early; op counts would be off")
        counted.append(ops.by_op())
    per_step = {
        name: (counted[1][name] - counted[0][name]) / 10
        for name in counted[1] | counted[0]
    }
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        sims[1].rollout(x, seeds)
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events) or 1
    by_time = sorted(events, key=lambda e: -e.self_cpu_time_total)[:top]
    return {
        "scenario": scenario,
        "batch_size": batch_size,
        "compiled": sims[0].simulator.compile,
        "ops_per_step": sum(per_step.values()),
        "syncs_per_step": sum(per_step.get(name, 0.0) for name in SYNC_OPS),
        "top_ops_by_count": dict(sorted(per_step.items(), key=lambda kv: -kv[1])[:top]),
        "top_ops_by_self_time_pct": {
            e.key: round(100 * e.self_cpu_time_total / total, 1) for e in by_time
        },
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch-size", type=int, default=2048)
    parser.add_argument("--steps", type=int, default=5, help="Base rollout length.")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    rows = [
        profile_scenario(s, args.batch_size, args.steps, args.top)
        for s in args.scenarios.split(",")
    ]
    for r in rows:
        mode = "compiled" if r["compiled"] else "eager"
        print(
            f"\n{r['scenario']} ({mode}, batch {r['batch_size']}): "
            f"{r['ops_per_step']:,.0f} ops per step, "
            f"{r['syncs_per_step']:g} host syncs per step"
        )
        print(
            "  by count: "
            + ", ".join(f"{k} {v:g}" for k, v in r["top_ops_by_count"].items())
        )
        print(
            "  by self time [%]: "
            + ", ".join(f"{k} {v}" for k, v in r["top_ops_by_self_time_pct"].items())
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
