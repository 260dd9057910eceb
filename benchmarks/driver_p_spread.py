"""p under other traffic drivers, the ego held fixed: how much p depends on P0.

``p`` is a probability under ``P0``, and ``P0``'s traffic is the learned
driver model. This runs one estimation of a scenario (default
``highway_default``) per driver folder (e.g. the six seeds of
``benchmarks/driver_seed_study.py``) and brake, with the traffic swapped
(:class:`avrisk.assembly.traffic.TrafficDrivers`: their network, their
``xi`` prior, their brake or none) while the ``lidar_imitation`` ego keeps the
shipped weights, and prints each ``p`` with its interval, then the spread
over the driver folders as its own interval beside them (not folded into the
estimator's: the estimators' coverage is measured under fixed drivers)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/driver_p_spread.py \\
        --drivers runs/driver_seeds/all_shipped/seed-{0..5} --brakes own none \\
        --method splitting_is --out runs/p_spread

Each run goes to ``OUT/<label>_<brake>`` (resumed or read back when run
again, as ``avrisk run`` does) and its row to ``OUT/p_spread.jsonl``. The
samples are stored whole (``store_full``), so that nothing is drawn again
from another prior when read.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from avrisk.agents.drivers.store import default_drivers_dir
from avrisk.api.runs import execute, method_label, scenario_spec, settings
from avrisk.assembly.objective import SimulationObjective
from avrisk.assembly.traffic import OWN_GUARD, TrafficDrivers
from avrisk.pipeline.store import SUMMARY_FILE

#: ``--brakes`` values: the brake the weights carry, or none.
BRAKES = {"own": OWN_GUARD, "none": None}


def _option(text: str) -> tuple[str, object]:
    key, _, value = text.partition("=")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def estimate(
    scenario: str,
    folder: Path | None,
    brake: str,
    out: Path,
    method: str,
    gamma: float,
    seed: int,
    options: dict[str, object],
) -> dict[str, object]:
    """One estimation with ``folder``'s drivers as traffic (None: the shipped)."""
    spec = scenario_spec(scenario)
    folder = default_drivers_dir() if folder is None else folder
    traffic = TrafficDrivers(folder, BRAKES[brake])
    objective = SimulationObjective(spec, traffic=traffic)
    run_settings = settings(method, gamma=gamma, seed=seed, **options)
    t0 = time.perf_counter()
    run_dir = execute(
        method_label(method),
        out,
        objective,
        spec.model_dump(mode="json"),
        run_settings,
        failures=0,
        store_full=True,
    )
    summary = json.loads((run_dir.path / SUMMARY_FILE).read_text())
    est = summary["estimate"]
    return {
        "drivers": str(folder),
        "brake": brake,
        "scenario": spec.name,
        "method": method,
        "seed": seed,
        "gamma": est["gamma"],
        "p": est["p"],
        "stderr": est["stderr"],
        "ci": est["ci"],
        "n_hits": est["n_hits"],
        "n_evals": est["n_evals"],
        "seconds": round(time.perf_counter() - t0, 1),
        "defines_p": objective.definition(),
    }


def spread(rows: list[dict[str, object]]) -> dict[str, float] | None:
    """The spread of ``p`` over driver folders: range and log-scale sd.

    None for fewer than two estimates or any zero.
    """
    p = np.array([float(r["p"]) for r in rows])
    if len(p) < 2 or (p <= 0).any():
        return None
    log_p = np.log(p)
    return {
        "n": len(p),
        "min": float(p.min()),
        "max": float(p.max()),
        "geometric_mean": float(math.exp(log_p.mean())),
        "log_sd": float(log_p.std(ddof=1)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway_default")
    parser.add_argument("--drivers", nargs="+", type=Path, required=True)
    parser.add_argument("--brakes", nargs="+", default=["own"], choices=BRAKES)
    parser.add_argument("--method", default="splitting_is")
    parser.add_argument("--gamma", type=float, default=0.1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--option", nargs="*", default=[], type=_option)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for brake in args.brakes:
        for folder in args.drivers:
            label = "_".join(folder.parts[-2:])
            row = estimate(
                args.scenario,
                folder,
                brake,
                args.out / f"{label}_{brake}",
                args.method,
                args.gamma,
                args.seed,
                dict(args.option),
            )
            rows.append(row)
            with open(args.out / "p_spread.jsonl", "a") as f:
                f.write(json.dumps(row) + "\n")
            lo, hi = row["ci"]
            print(
                f"{label} brake={brake}: p({row['gamma']:g}) = {row['p']:.3g} "
                f"[{lo:.3g}, {hi:.3g}] ({row['n_hits']} hits, {row['n_evals']:,} "
                f"rollouts, {row['seconds']:.0f} s)",
                flush=True,
            )
    for brake in args.brakes:
        s = spread([r for r in rows if r["brake"] == brake])
        if s is not None:
            print(
                f"spread over {s['n']} driver models, brake={brake}: p from "
                f"{s['min']:.3g} to {s['max']:.3g} (geometric mean "
                f"{s['geometric_mean']:.3g}, sd of log p {s['log_sd']:.2f})"
            )


if __name__ == "__main__":
    main()
