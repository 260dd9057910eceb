"""Coverage of the estimators against a large naive reference (issue 19, item 2).

Each estimator runs at a fixed budget on a bundled scenario for many seeds; the
runs are judged against a naive reference of millions of rollouts
(``benchmarks/reference.py``), with the reference's own error allowed for.

``run`` appends one JSON line per seed to ``--out`` (seeds already there are
skipped, so an interrupted sweep goes on where it stopped)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/coverage.py run highway_idm \\
        --preset ce --seeds 0-19 --out benchmarks/results/coverage/highway_idm.jsonl

``table`` prints, per preset and threshold, as markdown::

    .venv/bin/python benchmarks/coverage.py table \\
        --reference benchmarks/results/references/highway_idm.json \\
        benchmarks/results/coverage/highway_idm.jsonl

* mean relative bias against the reference, with its standard error (the
  spread over seeds and the reference's error combined);
* coverage: a run covers when the reference lies within
  ``p_hat -/+ sqrt(h^2 + (1.96 se_ref)^2)``, ``h`` that side's half-width of the
  run's own 95% interval (so a noisy reference does not fail an honest
  estimator); the unwidened count beside it;
* calibration: the runs' mean half-width over 1.96 times the spread of the
  estimates over seeds (1 is honest; below 1 the intervals are too narrow,
  above 1 wider than they need be);
* variance ratio: the naive binomial variance at the same budget,
  ``p_ref (1 - p_ref) / n``, over the variance of the estimates across seeds;
* median Pareto k of the hits' weights; mean wall time per run.

Every line records the scenario's definition (the hash of the resolved spec and
of the driver weights); ``table`` refuses a reference computed on another.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch

#: Settings of each preset: the estimator and its settings, at 20,000 rollouts
#: (search included; splitting's cost depends on its number of levels).
PRESETS: dict[str, tuple[str | None, dict[str, Any]]] = {
    "ce": ("ce", dict(rho=0.1, alpha=0.8, n_per_iter=2000, n_iter=5, n_final=10_000)),
    "defensive": (
        "defensive",
        dict(rho=0.1, alpha=0.8, n_per_iter=2000, n_iter=5, n_final=10_000),
    ),
    "mixture": (
        "mixture",
        dict(rho=0.1, alpha=0.8, n_per_iter=2000, n_iter=5, n_final=10_000),
    ),
    "splitting": ("splitting", dict(n_particles=4000, p0=0.1)),
    "splitting_is": ("splitting_is", dict(n_particles=2000, p0=0.1, n_final=10_000)),
    "naive": ("naive", dict(n_final=20_000)),
    # what ``avrisk run SCENARIO`` does: the default method at its own defaults
    "default": (None, {}),
}


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def _assignment(text: str) -> tuple[str, Any]:
    """``NAME=VALUE`` of ``--set``, the value read as YAML (a number, a word)."""
    import yaml

    name, sep, value = text.partition("=")
    if not sep:
        raise SystemExit(f"--set takes NAME=VALUE; got {text!r}")
    return name.strip(), yaml.safe_load(value)


def _done_seeds(out: Path, preset: str) -> set[int]:
    if not out.exists():
        return set()
    lines = (json.loads(line) for line in out.read_text().splitlines() if line)
    return {r["seed"] for r in lines if r["preset"] == preset}


def _commit() -> str:
    """The short git commit of the avrisk checkout the run imports, or "unknown"."""
    from avrisk.pipeline.provenance import code_version

    return (code_version()["git_commit"] or "unknown")[:7]


def run(args: argparse.Namespace) -> None:
    """Run one preset for the seeds not yet in ``args.out``."""
    from avrisk.assembly import SimulationObjective, base_distribution
    from avrisk.rare import estimate as estimate_p
    from avrisk.rare.estimator import DEFAULT_METHOD
    from avrisk.rare.splitting_levels import SplittingError
    from avrisk.report.answer import threshold_trust
    from avrisk.scenario import load_spec

    torch.set_num_threads(args.threads)
    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec, device=args.device)
    base = base_distribution(spec)
    method, settings = PRESETS[args.preset]
    method = method or DEFAULT_METHOD
    overrides = dict(_assignment(text) for text in args.set)
    settings = {**settings, **overrides}
    preset = args.preset + "".join(f" {k}={v}" for k, v in overrides.items())
    gamma_test = tuple(float(g) for g in args.gamma_test.split(","))
    done = _done_seeds(args.out, preset)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    commit = _commit()
    for seed in _seeds(args.seeds):
        if seed in done:
            continue
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # low-hit runs warn; recorded below
            try:
                estimate = estimate_p(
                    method,
                    objective,
                    base,
                    args.gamma,
                    seed=seed,
                    gamma_test=gamma_test,
                    batch_size=args.batch_size,
                    **settings,
                )
            except SplittingError as err:  # the levels ran out: the user's error
                _record(args.out, {"preset": preset, "seed": seed, "error": str(err)})
                print(f"{args.scenario} {preset} seed {seed}: {err}", file=sys.stderr)
                continue
        seconds = time.perf_counter() - start
        as_dict = estimate.to_dict()
        summary = {"method": method, "estimate": as_dict}
        trust = {  # the CLI's label at every threshold
            f"{g['gamma']:g}": str(threshold_trust(summary, g))
            for g in as_dict["by_gamma"]
        }
        record = {
            "preset": preset,
            "method": method,
            "settings": settings,
            "scenario": args.scenario,
            "seed": seed,
            "n_evals": estimate.n_evals,
            "seconds": seconds,
            "by_gamma": [g.to_dict() for g in estimate.by_gamma.values()],
            "trust": trust,
            # the proposal's choices, where the estimator makes some
            "fit": {
                key: estimate.details[key]
                for key in (
                    "informative_threshold",
                    "along_slope",
                    "fitted_variances",
                    "n_components",
                    "answer",
                )
                if key in (estimate.details or {})
            },
            "defines_p": objective.definition(),
            "computed_with": objective.computed_with(),
            "commit": commit,
        }
        _record(args.out, record)
        print(
            f"{args.scenario} {preset} seed {seed}: p={estimate.p:.3g} "
            f"+-{estimate.stderr:.2g} n={estimate.n_evals:,} ({seconds:.0f} s)",
            file=sys.stderr,
            flush=True,
        )


def _record(out: Path, record: dict[str, Any]) -> None:
    """Append one run's JSON line."""
    with out.open("a") as stream:
        stream.write(json.dumps(record) + "\n")


def widened(
    p: np.ndarray, lo: np.ndarray, hi: np.ndarray, se_ref: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each run's 95% interval widened by the reference's own error.

    ``p -/+ sqrt(h^2 + (1.96 se_ref)^2)``, ``h`` that side's half-width: a run
    covers when the reference lies within it.

    Parameters
    ----------
    p, lo, hi : ndarray of shape (s,)
        Each run's estimate and 95% interval.
    se_ref : float
        The reference's standard error.

    Returns
    -------
    low, high : ndarray of shape (s,)
    """
    widen = (1.96 * se_ref) ** 2
    return p - np.sqrt((p - lo) ** 2 + widen), p + np.sqrt((hi - p) ** 2 + widen)


def labels(
    runs: list[dict[str, Any]],
    gamma: float,
    p: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    p_ref: float,
    se_ref: float,
) -> dict[str, int | None]:
    """How the CLI's trust label judged the runs at one threshold.

    Runs labelled ``ok``; of them, those covering the reference (widened by
    its error, as :func:`judge` counts) and those off by more than 2 times
    either way. None where the runs recorded no label.
    """
    words = [(r.get("trust") or {}).get(f"{gamma:g}") for r in runs]
    if any(w is None for w in words):
        return {"ok": None, "ok_covering": None, "ok_off_2x": None}
    ok = np.array([w == "ok" for w in words])
    low, high = widened(p, lo, hi, se_ref)
    covering = (low <= p_ref) & (p_ref <= high)
    off = (p > 2 * p_ref) | (p < p_ref / 2)
    return {
        "ok": int(ok.sum()),
        "ok_covering": int((ok & covering).sum()),
        "ok_off_2x": int((ok & off).sum()),
    }


def judge(
    p: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    p_ref: float,
    se_ref: float,
    n: float,
) -> dict[str, float]:
    """The coverage figures of runs against a reference.

    Parameters
    ----------
    p, lo, hi : ndarray of shape (s,)
        Each run's estimate and 95% interval.
    p_ref, se_ref : float
        The reference estimate and its standard error.
    n : float
        Mean rollouts per run (for the naive variance at the same budget).
    """
    s = len(p)
    low, high = widened(p, lo, hi, se_ref)
    rel = p / p_ref - 1
    spread = p.std(ddof=1)
    # The bias's standard error: the spread over seeds and the reference's own.
    bias_se = math.hypot(rel.std(ddof=1) / math.sqrt(s), se_ref / p_ref)
    return {
        "seeds": s,
        "bias": float(rel.mean()),
        "bias_se": bias_se,
        "covered": int(((low <= p_ref) & (p_ref <= high)).sum()),
        "covered_unwidened": int(((lo <= p_ref) & (p_ref <= hi)).sum()),
        "above": int((low > p_ref).sum()),
        "below": int((high < p_ref).sum()),
        "calibration": float(((hi - lo) / 2).mean() / (1.96 * spread))
        if spread > 0
        else math.nan,
        "variance_ratio": p_ref * (1 - p_ref) / n / spread**2
        if spread > 0
        else math.inf,
    }


def table(args: argparse.Namespace) -> None:
    """Print the coverage table of every preset in the given files."""
    reference = json.loads(args.reference.read_text())
    ref = {g["gamma"]: g for g in reference["by_gamma"]}
    records = [
        json.loads(line)
        for path in args.results
        for line in path.read_text().splitlines()
        if line
    ]
    raised = [r for r in records if "error" in r]
    records = [r for r in records if "error" not in r]
    for record in records:
        if record["defines_p"] != reference["provenance"]["defines_p"]:
            sys.exit(
                f"{record['preset']} seed {record['seed']} was run on another "
                f"definition of p than the reference: {record['defines_p']} "
                f"vs {reference['provenance']['defines_p']}"
            )
    presets = list(dict.fromkeys(r["preset"] for r in records))
    gammas = [float(g) for g in args.gammas.split(",")]
    print(
        f"Reference: naive, {reference['n']:,} rollouts (seed {reference['seed']}). "
        "Coverage widened by the reference's error (unwidened in brackets).\n"
    )
    print(
        "| estimator | gamma [s] | p reference | seeds | rollouts/run | "
        "mean rel. bias +- se | covered (unwidened) | runs above / below | "
        "calibration | variance ratio | median Pareto k | s/run | raised | "
        "labelled ok (covering) | ok and off 2x |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    for preset in presets:
        runs = sorted(
            (r for r in records if r["preset"] == preset), key=lambda r: r["seed"]
        )
        n = float(np.mean([r["n_evals"] for r in runs]))
        seconds = float(np.mean([r["seconds"] for r in runs]))
        for g in gammas:
            per_run = [
                next((e for e in r["by_gamma"] if e["gamma"] == g), None) for r in runs
            ]
            per_run = [e for e in per_run if e is not None]
            if len(per_run) < 2 or g not in ref:
                continue
            p = np.array([e["p"] for e in per_run])
            lo = np.array([e["ci"][0] for e in per_run])
            hi = np.array([e["ci"][1] for e in per_run])
            pk = [e["pareto_k"] for e in per_run if e["pareto_k"] is not None]
            figures = judge(p, lo, hi, ref[g]["p"], ref[g]["stderr"], n)
            figures |= labels(runs, g, p, lo, hi, ref[g]["p"], ref[g]["stderr"])
            figures["raised"] = sum(r["preset"] == preset for r in raised)
            row = {
                "preset": preset,
                "gamma": g,
                "p_reference": ref[g]["p"],
                "rollouts": n,
                "seconds": seconds,
                "median_pareto_k": float(np.median(pk)) if pk else math.nan,
                **figures,
            }
            rows.append(row)
            print(
                f"| {preset} | {g:g} | {ref[g]['p']:.3g} | {figures['seeds']} "
                f"| {n:,.0f} | {figures['bias']:+.1%} +- {figures['bias_se']:.1%} "
                f"| {figures['covered']} ({figures['covered_unwidened']}) "
                f"| {figures['above']} / {figures['below']} "
                f"| {figures['calibration']:.2f} "
                f"| {figures['variance_ratio']:.0f}x "
                f"| {row['median_pareto_k']:.2f} | {seconds:.0f} "
                f"| {figures['raised']} | {figures['ok']} ({figures['ok_covering']}) "
                f"| {figures['ok_off_2x']} |"
            )
    if args.json:
        args.json.write_text(json.dumps({"reference": reference, "rows": rows}))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    runner = commands.add_parser("run", help="Run one preset for many seeds.")
    runner.add_argument("scenario")
    runner.add_argument("--preset", choices=sorted(PRESETS), required=True)
    runner.add_argument(
        "--set",
        action="append",
        default=[],
        help="NAME=VALUE: a setting of the preset changed (named in the results).",
    )
    runner.add_argument("--seeds", default="0-19", help="FIRST-LAST, inclusive.")
    runner.add_argument("--gamma", type=float, default=0.1)
    runner.add_argument("--gamma-test", default="0.3,0.5")
    runner.add_argument("--batch-size", type=int, default=4096)
    runner.add_argument("--threads", type=int, default=1)
    runner.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N.")
    runner.add_argument("--out", type=Path, required=True)
    runner.set_defaults(action=run)
    tabler = commands.add_parser("table", help="Judge the runs against a reference.")
    tabler.add_argument("results", type=Path, nargs="+")
    tabler.add_argument("--reference", type=Path, required=True)
    tabler.add_argument("--gammas", default="0.1,0.3,0.5")
    tabler.add_argument("--json", type=Path)
    tabler.set_defaults(action=table)
    args = parser.parse_args(argv)
    args.action(args)


if __name__ == "__main__":
    main()
