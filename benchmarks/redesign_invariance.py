"""Fingerprint of small runs, to show that a refactoring changes no result.

One JSON line per check, in a digest file that two checkouts diff:

* ``avrisk run`` with naive Monte Carlo, cross-entropy and CE with a defensive
  final stage on both bundled scenarios, then every other registered method
  (the ``defensive`` method, ``mixture``, ``splitting``, ``splitting_is``) on
  ``highway_idm``, at fixed seeds and small budgets: every threshold's ``p``,
  standard error, interval, hits, ESS and Pareto k, a SHA-256 of the samples
  table's ``f``, ``log_weight`` and ``seed`` columns in sample order (every
  rollout, bit for bit), and one of the ``--json`` document (the answer,
  trust, diagnostics; the temporary folder's name taken out);
* ``avrisk compare`` of cross-entropy at a small budget (the same, per part,
  and its ``--json`` document with the ratios);
* ``avrisk simulate`` and ``avrisk replay --worst 2``: the rollouts table's
  columns and what ``replay`` prints;
* ``avrisk realism`` on a few held-out windows and one scene: ``realism.json``
  (its provenance, which holds timings and the command, left out),
  ``realism.md`` (its command line left out) and the two figures' bytes;
* the driver training of ``avrisk train-drivers --seed 0``: with ``--train
  tiny`` (the default) the same recipe at a tiny budget
  (:data:`TINY_TRAINING`, a minute), with ``--train full`` the command
  itself (minutes), with ``--train none`` skipped; the bytes of
  ``driver_net.npz`` and ``xi_prior.npz`` and ``training_report.json``
  without its timings.

Run it before and after a change and compare the digests with ``diff``::

    .venv/bin/python benchmarks/redesign_invariance.py --out before.jsonl
    # ... change the code ...
    .venv/bin/python benchmarks/redesign_invariance.py --out after.jsonl
    diff before.jsonl after.jsonl && echo unchanged

Between two checkouts, run it with each checkout first on ``PYTHONPATH``.
Every command runs with one torch thread, so the digest depends on the code
and the machine's kernels, not on the load.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

CE_SEARCH = ["--n-iter", "3", "--n-per-iter", "1000", "--n-final", "2000"]
RUNS = {
    "naive": ["--method", "naive", "--n-final", "3000"],
    "ce": ["--method", "ce", *CE_SEARCH, "--rho", "0.05"],
    "defensive": ["--method", "ce", *CE_SEARCH, "--defensive", "0.1", "--rho", "0.05"],
}
#: The other registered methods, on the cheaper scenario only.
MORE_RUNS = {
    "defensive_method": ["--method", "defensive", *CE_SEARCH, "--rho", "0.05"],
    "mixture": [
        *("--method", "mixture", "--n-iter", "3", "--n-per-iter", "1000"),
        *("--n-final", "2000", "--set", "n_components=2"),
    ],
    "splitting": [
        *("--method", "splitting", "--set", "n_particles=300"),
        *("--set", "max_levels=6"),
    ],
    "splitting_is": [
        *("--method", "splitting_is", "--set", "n_particles=300"),
        *("--set", "max_levels=6", "--n-final", "600"),
    ],
}
SCENARIOS = ("highway_idm", "highway_default")
CHEAP = "highway_idm"
COMMON = ["--gamma", "0.5", "--gamma-test", "0.1,1.0,2.0"]
COMMON += ["--seed", "3", "--batch-size", "700", "--failures", "0"]
COMPARE = ["--method", "ce", "--n-iter", "2", "--n-per-iter", "500"]
COMPARE += ["--n-final", "1000", "--rho", "0.05", "--reference-n", "2000"]
REALISM = ["--replicates", "1", "--scenes", "1", "--windows", "4", "--seed", "0"]
#: ``train-drivers --seed 0``'s recipe at a tiny budget (``--train tiny``).
TINY_TRAINING = dict(
    n_members=6,
    trunk_epochs=1,
    head_epochs=1,
    n_sim_rollouts=16,
    n_sim_val_rollouts=4,
    dagger_iters=1,
    dagger_rollouts=8,
    dagger_epochs=1,
    calibration_windows=8,
    calibration_steps=20,
)
TINY_CLOSED_LOOP = dict(iterations=2, batch_windows=4, window_steps=30)


def sha(data: bytes) -> str:
    """The first 16 hex digits of the SHA-256 of ``data``."""
    return hashlib.sha256(data).hexdigest()[:16]


def json_sha(doc: Any, tmp: Path) -> str:
    """A hash of a JSON document, the temporary folder's name replaced."""
    return sha(json.dumps(doc, sort_keys=True).replace(str(tmp), "<tmp>").encode())


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


class Checks:
    """Runs ``avrisk`` commands in a temporary folder, writing one line per check."""

    def __init__(self, avrisk: list[str], tmp: Path, out: Any) -> None:
        self.avrisk, self.tmp, self.out = avrisk, tmp, out

    def command(self, *args: str) -> str:
        """Run ``avrisk *args``; its stdout, or exit with its stderr."""
        cmd = [*self.avrisk, *args]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode:
            sys.exit(f"{' '.join(cmd)} failed:\n{done.stderr}")
        return done.stdout

    def line(self, **fields: Any) -> None:
        """One line of the digest."""
        self.out.write(json.dumps(fields) + "\n")
        self.out.flush()

    def run(self, scenario: str, name: str, options: list[str]) -> None:
        out = self.tmp / f"{scenario}-{name}"
        args = ["run", scenario, "--out", str(out), *COMMON, *options, "--json"]
        doc = json.loads(self.command(*args))
        self.line(
            scenario=scenario,
            run=name,
            **fingerprint(out),
            json_sha256=json_sha(doc, self.tmp),
        )

    def compare(self) -> None:
        out = self.tmp / "compare"
        args = ["compare", CHEAP, "--out", str(out), *COMMON, *COMPARE, "--json"]
        doc = json.loads(self.command(*args))
        for part in sorted(p.name for p in out.iterdir() if p.is_dir()):
            if (out / part / "summary.json").is_file():
                self.line(scenario=CHEAP, compare=part, **fingerprint(out / part))
        self.line(scenario=CHEAP, compare="json", json_sha256=json_sha(doc, self.tmp))

    def simulate(self) -> None:
        out = self.tmp / "rollouts.parquet"
        self.command("simulate", CHEAP, "--n", "300", "--seed", "1", "--out", str(out))
        table = pq.read_table(out)
        digest = hashlib.sha256()
        for name in table.column_names:  # text by value, not object pointers
            values = table[name].to_numpy()
            if values.dtype == object:
                digest.update(json.dumps(values.tolist()).encode())
            else:
                digest.update(np.ascontiguousarray(values).tobytes())
        gif = self.tmp / "replay.gif"
        printed = self.command("replay", str(out), "--worst", "2", "--out", str(gif))
        self.line(
            scenario=CHEAP,
            simulate=table.num_rows,
            columns_sha256=digest.hexdigest()[:16],
            replay=printed.replace(str(self.tmp), "<tmp>").splitlines(),
        )

    def realism(self) -> None:
        out = self.tmp / "realism"
        self.command("realism", *REALISM, "--out", str(out))
        doc = json.loads((out / "realism.json").read_text())
        doc.pop("provenance")
        text = (out / "realism.md").read_text().splitlines()
        self.line(
            realism_json=json_sha(doc, self.tmp),
            realism_md=sha("\n".join(t for t in text if "_Command:" not in t).encode()),
            **{p.name: sha(p.read_bytes()) for p in sorted(out.glob("*.png"))},
        )

    def training(self, kind: str) -> None:
        out = self.tmp / "drivers"
        if kind == "full":
            self.command("train-drivers", "--seed", "0", "--out", str(out))
        else:
            train_tiny(out)
        report = json.loads((out / "training_report.json").read_text())
        self.line(
            training=kind,
            **{p.name: sha(p.read_bytes()) for p in sorted(out.glob("*.npz"))},
            report=json_sha(without_timings(report), self.tmp),
        )


def without_timings(doc: Any) -> Any:
    """``doc`` without the keys that hold wall-clock times or dates."""
    if isinstance(doc, dict):
        return {
            k: without_timings(v)
            for k, v in doc.items()
            if not any(w in k for w in ("second", "time", "date", "wall"))
        }
    if isinstance(doc, list):
        return [without_timings(v) for v in doc]
    return doc


def train_tiny(out: Path) -> None:
    """``train_drivers(0, out)`` with :data:`TINY_TRAINING`'s budget."""
    from dataclasses import replace

    from avrisk.learning.train_config import TrainConfig
    from avrisk.learning.training.train import train_drivers

    default = TrainConfig()
    closed_loop = replace(default.closed_loop, **TINY_CLOSED_LOOP)
    config = replace(default, closed_loop=closed_loop, **TINY_TRAINING)
    train_drivers(0, out, config=config)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--out", type=Path, help="Digest file to write [default: stdout]."
    )
    parser.add_argument(
        "--train",
        choices=("tiny", "full", "none"),
        default="tiny",
        help="The driver training: at a tiny budget, train-drivers --seed 0 "
        "itself, or none.",
    )
    args = parser.parse_args()
    os.environ["OMP_NUM_THREADS"] = "1"
    avrisk = [sys.executable, "-m", "avrisk"]
    with (
        tempfile.TemporaryDirectory() as tmp,
        open(args.out, "w") if args.out else sys.stdout as out,
    ):
        checks = Checks(avrisk, Path(tmp), out)
        for scenario in SCENARIOS:
            for name, options in RUNS.items():
                checks.run(scenario, name, options)
        for name, options in MORE_RUNS.items():
            checks.run(CHEAP, name, options)
        checks.compare()
        checks.simulate()
        checks.realism()
        if args.train != "none":
            checks.training(args.train)


if __name__ == "__main__":
    main()
