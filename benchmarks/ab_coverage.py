"""Paired comparison of two versions: coverage and efficiency on exact pairs (issue 45).

Runs the paired estimator (:func:`avrisk.rare.paired.paired_splitting_is`:
``splitting_is`` on ``min(f_A, f_B)``, every figure from its one weighted
sample) on the analytic pairs of :mod:`avrisk.testing.pairs` (half-spaces in
standard-normal space, exact ``p_A``, ``p_B`` and ``p_AB``) and, on the same
seeds, two independent ``splitting_is`` runs, one per version, with half a
default single-version run's particles and final samples each (about half
the paired run's evaluations of a version). ``run-even`` (a file of its own)
runs the paired estimator at half its default samples (``EVEN``): about as
many evaluations of a version as the two independent runs together, the fair
comparison of their spreads::

    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_coverage.py run \\
        [--cases nested_r0.05_p1e-04_d10,...] [--seeds 0-199] \\
        [--out benchmarks/results/ab/runs.jsonl] [--independent-from EARLIER.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_coverage.py run-even \\
        [--seeds 0-199] [--out benchmarks/results/ab/even_runs.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_coverage.py run-single \\
        [--seeds 0-199] [--out benchmarks/results/ab/single_runs.jsonl]
    python benchmarks/ab_coverage.py table [--results ...] [--even ...] \\
        [--single ...] [--md T.md] [--json T.json]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_coverage.py gate \
        [--seeds 0-19] [--out benchmarks/results/ab/gate.json]

One setting for every case (``PAIRED``, ``INDEPENDENT``). ``run`` appends one
JSON line per (case, seed) and skips those already there, so an interrupted
sweep goes on. ``table`` prints per case:

* coverage of the 95% intervals of ``p_A``, ``p_B``, ``p_B - p_A`` and ``p_B
  / p_A`` (runs whose interval holds the exact value), and how often the
  exact ratio lies below the one-sided lower 95% bound or above the upper one
  (what a CI gate reads; each should be at most about 5%);
* with ``--single`` (``run-single``: two independent runs at a default
  single-version run's settings, ``SINGLE``, about the default paired run's
  evaluations), the efficiency at the default budget;
* efficiency: the spread (standard deviation over seeds) of the paired
  estimate of ``p_B - p_A`` and of the difference of the two independent
  runs' estimates, their ratio (``> 1``: the paired one is narrower), and
  both methods' mean evaluations of a version; with ``--even``, the same at
  equal evaluations (the even paired runs);
* runs the engine's trust rule labelled ``caution``.

``gate`` runs the gate (:func:`avrisk.rare.paired.gate`, margin 1) on the
paired run of ``GATE_CASES`` (a ``B`` with half ``A``'s ``p``, one with twice
it, two with the same ``p`` as ``A`` on other failure sets) over 20 seeds at
the same setting, and counts each outcome.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from avrisk.rare.paired import paired_splitting_is  # noqa: E402
from avrisk.rare.paired_gate import gate  # noqa: E402
from avrisk.rare.splitting_importance import splitting_is  # noqa: E402
from avrisk.testing.ab_budgets import (  # noqa: E402
    EVEN,
    INDEPENDENT,
    PAIRED,
    SINGLE,
)
from avrisk.testing.pairs import PAIR_SUITE, AnalyticPair, pair_problem  # noqa: E402

DEFAULT_OUT = ROOT / "benchmarks" / "results" / "ab" / "runs.jsonl"
GATE_OUT = ROOT / "benchmarks" / "results" / "ab" / "gate.json"
#: The gate's cases: what B is, by the pair that makes it.
GATE_CASES = {
    "half": "nested_r0.5_p1e-04_d10",
    "twice": "disjoint_ratio2_p1e-04_d10",
    "equal, overlapping": "overlap_r0.3_p1e-04_d10",
    "equal, disjoint": "disjoint_ratio1_p1e-04_d10",
}

SINGLE_OUT = ROOT / "benchmarks" / "results" / "ab" / "single_runs.jsonl"
EVEN_OUT = ROOT / "benchmarks" / "results" / "ab" / "even_runs.jsonl"
#: Offset of the independent runs' seeds (2 per paired seed), so that no
#: independent run shares a paired run's draws.
INDEPENDENT_SEED = 1_000_000


def paired_record(pair: AnalyticPair, seed: int) -> dict[str, Any]:
    """One paired run's figures against the exact ones."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = paired_splitting_is(pair.f, pair.base, pair.gamma, seed=seed, **PAIRED)
    truth = {
        "a": pair.p_a,
        "b": pair.p_b,
        "difference": pair.difference,
        "ratio": pair.ratio,
    }
    parts = {
        "a": est.a,
        "b": est.b,
        "difference": est.difference,
        "ratio": est.ratio,
    }
    out: dict[str, Any] = {}
    for key, part in parts.items():
        value = part.p if key in ("a", "b") else part.value
        lo, hi = part.ci
        out[key] = {"value": value, "ci": [lo, hi], "covers": lo <= truth[key] <= hi}
    out["ratio"]["below_lower"] = pair.ratio < est.ratio.lower
    out["ratio"]["above_upper"] = pair.ratio > est.ratio.upper
    out["n_evals"] = est.n_evals
    out["discordant"] = est.regressions.n_hits + est.fixes.n_hits
    out["trust"] = est.trust.word
    out["reasons"] = list(est.trust.reasons)
    return out


def independent_record(
    pair: AnalyticPair, seed: int, settings: dict[str, int] = INDEPENDENT
) -> dict[str, Any]:
    """Two independent runs, one per version: their estimates and calls."""
    estimates = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for which in (0, 1):
            problem = pair.version(which)
            run_seed = INDEPENDENT_SEED + 2 * seed + which
            estimates.append(
                splitting_is(
                    problem.f, problem.base, problem.gamma, seed=run_seed, **settings
                )
            )
    a, b = estimates
    return {"a": a.p, "b": b.p, "n_evals": a.n_evals + b.n_evals}


def _done(out: Path) -> set[tuple[str, int]]:
    """The (case, seed) pairs ``out`` holds."""
    if not out.is_file():
        return set()
    return {
        (r["case"], r["seed"]) for r in map(json.loads, out.read_text().splitlines())
    }


def _append_missing(
    cases: list[str],
    seeds: list[int],
    out: Path,
    record: Callable[[AnalyticPair, str, int], dict[str, Any]],
) -> None:
    """Append ``record(pair, case, seed)`` per (case, seed) not yet in ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    done = _done(out)
    with out.open("a") as sink:
        for name in cases:
            pair = pair_problem(name)
            for seed in seeds:
                if (name, seed) in done:
                    continue
                sink.write(json.dumps(record(pair, name, seed)) + "\n")
                sink.flush()
            print(f"{name}: done", flush=True)


def run_even(cases: list[str], seeds: list[int], out: Path) -> None:
    """Append the even paired run's difference per (case, seed) not yet in ``out``."""

    def record(pair: AnalyticPair, name: str, seed: int) -> dict[str, Any]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = paired_splitting_is(pair.f, pair.base, pair.gamma, seed=seed, **EVEN)
        return {
            "case": name,
            "seed": seed,
            "settings": EVEN,
            "difference": est.difference.value,
            "n_evals": est.n_evals,
        }

    _append_missing(cases, seeds, out, record)


def run_single(cases: list[str], seeds: list[int], out: Path) -> None:
    """Append two default single-version runs per (case, seed) not yet in ``out``."""

    def record(pair: AnalyticPair, name: str, seed: int) -> dict[str, Any]:
        return {
            "case": name,
            "seed": seed,
            "settings": SINGLE,
            **independent_record(pair, seed, SINGLE),
        }

    _append_missing(cases, seeds, out, record)


def parse_seeds(text: str) -> list[int]:
    """``"0-199"`` or ``"0,3,5"``."""
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def earlier_independent(path: Path | None) -> dict[tuple[str, int], dict[str, Any]]:
    """The independent runs of an earlier ``run`` file at today's ``INDEPENDENT``.

    They do not depend on the paired estimator, so a change of it leaves
    them bit for bit as they were: ``run --independent-from`` copies them
    instead of running them again.
    """
    if path is None:
        return {}
    return {
        (r["case"], r["seed"]): r["independent"]
        for r in map(json.loads, path.read_text().splitlines())
        if r["settings"]["independent"] == INDEPENDENT
    }


def run(
    cases: list[str], seeds: list[int], out: Path, reuse: Path | None = None
) -> None:
    """Append a line per (case, seed) not yet in ``out``.

    ``reuse``: an earlier ``run`` file whose independent runs are copied
    (:func:`earlier_independent`).
    """
    settings = {"paired": PAIRED, "independent": INDEPENDENT}
    earlier = earlier_independent(reuse)

    def record(pair: AnalyticPair, name: str, seed: int) -> dict[str, Any]:
        return {
            "case": name,
            "seed": seed,
            "settings": settings,
            "exact": {
                "p_a": pair.p_a,
                "p_b": pair.p_b,
                "p_ab": pair.p_ab,
                "r": pair.discordant_share,
            },
            "paired": paired_record(pair, seed),
            "independent": earlier.get((name, seed)) or independent_record(pair, seed),
        }

    _append_missing(cases, seeds, out, record)


def case_row(
    name: str,
    recs: list[dict[str, Any]],
    even: list[dict[str, Any]],
    single: list[dict[str, Any]] = (),
) -> dict[str, Any]:
    """The table's figures for one case.

    ``even``: its even paired runs; ``single``: its pairs of default
    single-version runs (``run-single``).
    """
    n = len(recs)
    exact = recs[0]["exact"]
    cover = {
        k: sum(r["paired"][k]["covers"] for r in recs)
        for k in ("a", "b", "difference", "ratio")
    }
    paired_diff = np.array([r["paired"]["difference"]["value"] for r in recs])
    indep_diff = np.array([r["independent"]["b"] - r["independent"]["a"] for r in recs])
    truth = exact["p_b"] - exact["p_a"]
    spread_paired = float(paired_diff.std(ddof=1))
    spread_indep = float(indep_diff.std(ddof=1))
    return (
        {
            "case": name,
            "runs": n,
            "r": exact["r"],
            "p_a": exact["p_a"],
            "p_b": exact["p_b"],
            "coverage": cover,
            "ratio_below_lower": sum(r["paired"]["ratio"]["below_lower"] for r in recs),
            "ratio_above_upper": sum(r["paired"]["ratio"]["above_upper"] for r in recs),
            "spread_paired": spread_paired,
            "spread_independent": spread_indep,
            "narrower_by": spread_indep / spread_paired
            if spread_paired > 0
            else math.inf,
            "bias_paired": float(paired_diff.mean() - truth),
            "calls_paired": float(np.mean([r["paired"]["n_evals"] for r in recs])),
            "calls_independent": float(
                np.mean([r["independent"]["n_evals"] for r in recs])
            ),
            "caution": sum(r["paired"]["trust"] != "ok" for r in recs),
        }
        | _even_figures(even, spread_indep, recs)
        | _single_figures(single, spread_paired)
    )


def _single_figures(
    single: list[dict[str, Any]], spread_paired: float
) -> dict[str, Any]:
    """The efficiency at the default budget: two default single-version runs'."""
    if len(single) < 2:
        return {}
    spread = float(np.std([r["b"] - r["a"] for r in single], ddof=1))
    return {
        "single_runs": len(single),
        "spread_single": spread,
        "narrower_by_single": spread / spread_paired if spread_paired > 0 else math.inf,
        "evaluations_single": float(np.mean([r["n_evals"] for r in single])),
    }


def _even_figures(
    even: list[dict[str, Any]], spread_indep: float, recs: list[dict[str, Any]]
) -> dict[str, Any]:
    """The efficiency at equal evaluations of a version: the even paired runs'."""
    if len(even) < 2:
        return {}
    spread = float(np.std([r["difference"] for r in even], ddof=1))
    return {
        "even_runs": len(even),
        "spread_even": spread,
        "narrower_by_even": spread_indep / spread if spread > 0 else math.inf,
        # each draw of a paired run is evaluated by both versions
        "evaluations_even": 2 * float(np.mean([r["n_evals"] for r in even])),
        "evaluations_independent": float(
            np.mean([r["independent"]["n_evals"] for r in recs])
        ),
    }


def _by_case(path: Path | None) -> dict[str, list[dict[str, Any]]]:
    """A results file's records by case (none: no file)."""
    by_case: dict[str, list[dict[str, Any]]] = {}
    if path is not None and path.is_file():
        for rec in map(json.loads, path.read_text().splitlines()):
            by_case.setdefault(rec["case"], []).append(rec)
    return by_case


def table(
    results: Path, even: Path | None = None, single: Path | None = None
) -> tuple[list[dict[str, Any]], str]:
    """Rows per case and the markdown of the coverage and efficiency tables.

    ``even``: the even paired runs (``run-even``), for the efficiency at equal
    evaluations of a version; without them the table compares the default
    paired run, which evaluates twice as many. ``single``: default
    single-version runs (``run-single``), for the efficiency at the default
    budget.
    """
    by_even, by_single = _by_case(even), _by_case(single)
    rows = [
        case_row(name, recs, by_even.get(name, []), by_single.get(name, []))
        for name, recs in _by_case(results).items()
    ]
    md = [
        "| case | r | p_A | p_B | runs | p_A | p_B | p_B - p_A | p_B / p_A | "
        "ratio < lower / > upper (one-sided 95%) | caution |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        c, n = row["coverage"], row["runs"]
        md.append(
            f"| {row['case']} | {row['r']:.2f} | {row['p_a']:.3g} | {row['p_b']:.3g} "
            f"| {n} | {c['a']}/{n} | {c['b']}/{n} | {c['difference']}/{n} "
            f"| {c['ratio']}/{n} | {row['ratio_below_lower']} / "
            f"{row['ratio_above_upper']} | {row['caution']} |"
        )
    total = sum(row["runs"] for row in rows)
    pooled = {k: sum(row["coverage"][k] for row in rows) for k in rows[0]["coverage"]}
    md.append(
        f"| pooled | | | | {total} | "
        + " | ".join(f"{pooled[k] / total:.1%}" for k in pooled)
        + " | | |"
    )
    md += [
        "",
        "| case | r | spread of p_B - p_A: paired, default | independent | "
        "independent / paired | evaluations of a version: paired | independent |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        md.append(
            f"| {row['case']} | {row['r']:.2f} | {row['spread_paired']:.3g} "
            f"| {row['spread_independent']:.3g} | {row['narrower_by']:.2f} "
            f"| {2 * row['calls_paired']:,.0f} | {row['calls_independent']:,.0f} |"
        )
    if all("spread_even" in row for row in rows):
        md += [
            "",
            "At equal evaluations of a version (the even paired runs):",
            "",
            "| case | r | runs | spread of p_B - p_A: paired, even | independent "
            "| independent / paired | evaluations: paired | independent |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            md.append(
                f"| {row['case']} | {row['r']:.2f} | {row['even_runs']} "
                f"| {row['spread_even']:.3g} | {row['spread_independent']:.3g} "
                f"| {row['narrower_by_even']:.2f} | {row['evaluations_even']:,.0f} "
                f"| {row['evaluations_independent']:,.0f} |"
            )
    if all("spread_single" in row for row in rows):
        md += [
            "",
            "At the default budget (the default paired run against two default "
            "single-version runs, `run-single`):",
            "",
            "| case | r | runs | spread of p_B - p_A: paired, default | two single "
            "runs | single / paired | evaluations: paired | single |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            md.append(
                f"| {row['case']} | {row['r']:.2f} | {row['single_runs']} "
                f"| {row['spread_paired']:.3g} | {row['spread_single']:.3g} "
                f"| {row['narrower_by_single']:.2f} | {2 * row['calls_paired']:,.0f} "
                f"| {row['evaluations_single']:,.0f} |"
            )
    return rows, "\n".join(md)


def gate_sweep(seeds: list[int], out: Path) -> dict[str, Any]:
    """The gate's outcomes at margin 1 per case of ``GATE_CASES``, over ``seeds``."""
    counts: dict[str, Any] = {}
    for label, name in GATE_CASES.items():
        pair = pair_problem(name)
        outcomes = []
        for seed in seeds:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = paired_splitting_is(
                    pair.f, pair.base, pair.gamma, seed=seed, **PAIRED
                )
            outcomes.append(gate(est, 1.0).outcome)
        counts[label] = {
            "case": name,
            "ratio": pair.ratio,
            **{o: outcomes.count(o) for o in ("pass", "fail", "inconclusive")},
        }
        print(label, counts[label], flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"settings": PAIRED, "seeds": seeds, **counts}, indent=1))
    return counts


def main(argv: list[str] | None = None) -> None:
    """``run`` or ``table`` (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--cases", default=",".join(PAIR_SUITE))
    r.add_argument("--seeds", default="0-199")
    r.add_argument("--out", type=Path, default=DEFAULT_OUT)
    r.add_argument(
        "--independent-from",
        type=Path,
        help="an earlier run file whose independent runs to copy",
    )
    t = sub.add_parser("table")
    t.add_argument("--results", type=Path, default=DEFAULT_OUT)
    t.add_argument("--even", type=Path, default=EVEN_OUT)
    t.add_argument("--single", type=Path, default=SINGLE_OUT)
    t.add_argument("--md", type=Path)
    t.add_argument("--json", type=Path)
    e = sub.add_parser("run-even")
    e.add_argument("--cases", default=",".join(PAIR_SUITE))
    e.add_argument("--seeds", default="0-199")
    e.add_argument("--out", type=Path, default=EVEN_OUT)
    o = sub.add_parser("run-single")
    o.add_argument("--cases", default=",".join(PAIR_SUITE))
    o.add_argument("--seeds", default="0-199")
    o.add_argument("--out", type=Path, default=SINGLE_OUT)
    g = sub.add_parser("gate")
    g.add_argument("--seeds", default="0-19")
    g.add_argument("--out", type=Path, default=GATE_OUT)
    args = parser.parse_args(argv)
    if args.command == "run":
        run(
            args.cases.split(","),
            parse_seeds(args.seeds),
            args.out,
            args.independent_from,
        )
        return
    if args.command == "run-single":
        run_single(args.cases.split(","), parse_seeds(args.seeds), args.out)
        return
    if args.command == "run-even":
        run_even(args.cases.split(","), parse_seeds(args.seeds), args.out)
        return
    if args.command == "gate":
        gate_sweep(parse_seeds(args.seeds), args.out)
        return
    rows, md = table(args.results, args.even, args.single)
    print(md)
    if args.md:
        args.md.write_text(md + "\n")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
