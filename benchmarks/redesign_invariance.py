"""Fingerprint of small runs, to show that a refactoring changes no estimate.

Runs ``avrisk run`` with naive Monte Carlo, cross-entropy and CE with a
defensive final stage on both bundled scenarios, at fixed seeds and small
budgets, and prints one JSON line per run: every threshold's ``p``, standard
error, interval, hits, ESS and Pareto k, plus a SHA-256 of the samples table's
``f`` and ``log_weight`` columns in sample order (every rollout, bit for bit).
Run it before and after a change and compare the outputs with ``diff``::

    .venv/bin/python benchmarks/redesign_invariance.py > before.jsonl
    # ... change the code ...
    .venv/bin/python benchmarks/redesign_invariance.py > after.jsonl
    diff before.jsonl after.jsonl && echo unchanged

About two minutes on two cores.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

RUNS = {
    "naive": ["--method", "naive", "--n-final", "3000"],
    "ce": [
        "--method",
        "ce",
        "--n-iter",
        "3",
        "--n-per-iter",
        "1000",
        "--n-final",
        "2000",
        "--rho",
        "0.05",
    ],
    "defensive": [
        "--method",
        "ce",
        "--n-iter",
        "3",
        "--n-per-iter",
        "1000",
        "--n-final",
        "2000",
        "--defensive",
        "0.1",
        "--rho",
        "0.05",
    ],
}
SCENARIOS = ("highway_idm", "highway_default")
COMMON = ["--gamma", "0.5", "--gamma-test", "0.1,1.0,2.0"]
COMMON += ["--seed", "3", "--batch-size", "700", "--failures", "0"]


def fingerprint(run_dir: Path) -> dict:
    """Estimates of a finished run and a hash of its per-rollout results."""
    summary = json.loads((run_dir / "summary.json").read_text())
    table = pq.read_table(run_dir / "samples.parquet")
    order = np.lexsort((table["sample_id"].to_numpy(), table["stage"].to_numpy()))
    digest = hashlib.sha256()
    for column in ("f", "log_weight", "seed"):
        digest.update(np.ascontiguousarray(table[column].to_numpy()[order]).tobytes())
    est = summary["estimate"]
    return {
        "n_evals": est["n_evals"],
        "by_gamma": [
            {
                k: g.get(k)
                for k in ("gamma", "p", "stderr", "ci", "n_hits", "ess", "pareto_k")
            }
            for g in est["by_gamma"]
        ],
        "rows": table.num_rows,
        "samples_sha256": digest.hexdigest()[:16],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--avrisk", default=str(Path(sys.executable).with_name("avrisk"))
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in SCENARIOS:
            for name, options in RUNS.items():
                out = Path(tmp) / f"{scenario}-{name}"
                cmd = [
                    args.avrisk,
                    "run",
                    scenario,
                    "--out",
                    str(out),
                    *COMMON,
                    *options,
                ]
                done = subprocess.run(cmd, capture_output=True, text=True)
                if done.returncode:
                    sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr}")
                line = {"scenario": scenario, "run": name, **fingerprint(out)}
                print(json.dumps(line), flush=True)


if __name__ == "__main__":
    main()
