"""Paired comparison of two versions on a scenario: spread and gate (issue 45).

The bundled pair's row of the efficiency table (``examples/ab_lidar``: the
shipped lidar ego ``A`` and its variant ``B`` whose lidar reads every range
30% long) and the gate's outcomes at the CLI's default budget. Per seed:

* the paired run, as ``avrisk ab`` makes it (:func:`avrisk.api.compare_egos`,
  its default settings: ``splitting_is`` on ``min(f_A, f_B)``), its
  estimates of ``p_A``, ``p_B``, ``p_B - p_A`` and ``p_B / p_A`` with their
  intervals, the discordant share and the gate's outcome at ``--max-ratio``;
* two independent ``splitting_is`` runs (:func:`avrisk.api.estimate`), one
  per ego, with half a default single-version run's particles and final
  samples each (about half the default paired run's rollouts), on seeds of
  their own (``INDEPENDENT_SEED + 2 seed`` and ``+ 1``);
* with ``run-independent`` (a file of its own), the independent runs alone:
  the efficiency needs their spread over more seeds than the default
  paired run, which costs as much again;
* with ``run-even`` (a file of its own), a paired run at half the default
  paired run's samples (``EVEN``): each of its draws is simulated with both
  egos, so it simulates about as many rollouts as the two independent runs
  together. The efficiency is the spread of this run's difference against
  theirs; the default paired run simulates twice as many rollouts.

::

    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run \\
        [--seeds 0-49] [--reverse] [--out benchmarks/results/ab/lidar_pair.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-independent \\
        [--seeds 0-49] [--out benchmarks/results/ab/lidar_pair_independent.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-even \\
        [--seeds 0-49] [--out benchmarks/results/ab/lidar_pair_even.jsonl]
    python benchmarks/ab_scenario.py table [--results ...] [--independent ...] \\
        [--even ...] [--md T.md]

Each command appends one JSON line per seed and skips seeds already there, so an
interrupted sweep goes on (each seed's run directories are temporary); a
second process may go down the seeds into the same file (``--reverse``). No
exact answer is known here, so ``table`` reports what needs none: the spread
(standard deviation over seeds) of the paired difference against that of the
independent runs' difference, their ratio at equal rollouts (what the
analytic pairs' table of ``ab_coverage.py`` reports against ``r``), the mean
discordant share ``r``, the gate's outcomes, and the rollouts each way.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from avrisk.api import compare_egos, estimate  # noqa: E402
from avrisk.rare.paired import PAIRED_DEFAULTS  # noqa: E402
from avrisk.rare.splitting_importance import SplittingISSettings  # noqa: E402

DEFAULT_OUT = ROOT / "benchmarks" / "results" / "ab" / "lidar_pair.jsonl"
SCENARIO = "highway_default"
EGOS = {
    which: ROOT / "examples" / "ab_lidar" / name
    for which, name in (("a", "lidar_ego.yaml"), ("b", "lidar_ego_degraded.yaml"))
}
#: Each independent run's settings: half a default single-version run's samples.
INDEPENDENT = {
    name: SplittingISSettings.model_fields[name].default // 2
    for name in ("n_particles", "n_final")
}
#: The paired run of the efficiency comparison, at half the default paired
#: run's samples: each of its draws is simulated with both egos, so it
#: simulates about as many rollouts as the two independent runs together.
EVEN = {name: value // 2 for name, value in PAIRED_DEFAULTS.items()}
RESULTS = ROOT / "benchmarks" / "results" / "ab"
EVEN_OUT = RESULTS / "lidar_pair_even.jsonl"
INDEPENDENT_OUT = RESULTS / "lidar_pair_independent.jsonl"
#: Offset of the independent runs' seeds, so none shares a paired run's draws.
INDEPENDENT_SEED = 1_000_000
#: The gate's margin on ``p_B / p_A``.
MAX_RATIO = 1.0


def _ego(which: str) -> dict[str, Any]:
    return yaml.safe_load(EGOS[which].read_text())


def paired_record(
    seed: int, scratch: Path, settings: dict[str, int] | None = None
) -> dict[str, Any]:
    """One paired run (``settings``: ``avrisk ab``'s defaults): its figures, verdict."""
    start = time.perf_counter()
    result = compare_egos(
        SCENARIO,
        _ego("a"),
        _ego("b"),
        out=scratch / "paired",
        max_ratio=MAX_RATIO,
        seed=seed,
        failures=0,
        **(settings or {}),
    )
    est = result.paired
    union = float(est.union["p"])
    out: dict[str, Any] = {
        key: {"value": part.p, "ci": list(part.ci)}
        for key, part in (("a", est.a), ("b", est.b))
    }
    for key, part in (("difference", est.difference), ("ratio", est.ratio)):
        out[key] = {
            "value": part.value,
            "ci": list(part.ci),
            "lower": part.lower,
            "upper": part.upper,
        }
    out |= {
        "regressions": est.regressions.p,
        "fixes": est.fixes.p,
        "r": (est.regressions.p + est.fixes.p) / union if union > 0 else math.nan,
        "n_evals": est.n_evals,
        "outcome": result.verdict.outcome,
        "trust": est.trust.word,
        "reasons": list(est.trust.reasons),
        "seconds": time.perf_counter() - start,
    }
    return out


def independent_record(seed: int, scratch: Path) -> dict[str, Any]:
    """Two independent runs, one per ego: their estimates and rollouts."""
    start = time.perf_counter()
    runs = {}
    for offset, which in enumerate(("a", "b")):
        result = estimate(
            SCENARIO,
            ego=_ego(which),
            out=scratch / which,
            seed=INDEPENDENT_SEED + 2 * seed + offset,
            failures=0,
            **INDEPENDENT,
        )
        runs[which] = result.estimate
    return {
        "a": runs["a"]["p"],
        "b": runs["b"]["p"],
        "n_evals": runs["a"]["n_evals"] + runs["b"]["n_evals"],
        "seconds": time.perf_counter() - start,
    }


def parse_seeds(text: str) -> list[int]:
    """``"0-49"`` or ``"0,3,5"``."""
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def _done(out: Path) -> set[int]:
    """The seeds ``out`` holds."""
    if not out.is_file():
        return set()
    return {json.loads(line)["seed"] for line in out.read_text().splitlines()}


def _append_per_seed(
    seeds: list[int],
    out: Path,
    record: Callable[[int, Path], dict[str, Any]],
    describe: Callable[[dict[str, Any]], str],
) -> None:
    """Append ``record(seed, scratch)`` per seed not yet in ``out``, and print it.

    ``out`` is read again before each seed, so two processes may share it;
    each seed's run directories live in a temporary ``scratch`` folder.
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        if seed in _done(out):
            continue
        with tempfile.TemporaryDirectory() as scratch, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = {"scenario": SCENARIO, "seed": seed, **record(seed, Path(scratch))}
        with out.open("a") as sink:
            sink.write(json.dumps(rec) + "\n")
        print(f"seed {seed}: {describe(rec)}", flush=True)


def run(seeds: list[int], out: Path) -> None:
    """Append the default paired run and the independent runs per seed.

    Two processes may share ``out``, e.g. one going up the seeds and one
    down (``--reverse``).
    """
    _append_per_seed(
        seeds,
        out,
        lambda seed, scratch: {
            "egos": {k: str(v.relative_to(ROOT)) for k, v in EGOS.items()},
            "independent_settings": INDEPENDENT,
            "paired": paired_record(seed, scratch),
            "independent": independent_record(seed, scratch),
        },
        lambda rec: (
            f"{rec['paired']['outcome']}, ratio {rec['paired']['ratio']['value']:.3g}, "
            f"{rec['paired']['seconds']:.0f} s + {rec['independent']['seconds']:.0f} s"
        ),
    )


def run_independent(seeds: list[int], out: Path) -> None:
    """Append the independent runs alone per seed not yet in ``out``."""
    _append_per_seed(
        seeds,
        out,
        lambda seed, scratch: {
            "independent_settings": INDEPENDENT,
            "independent": independent_record(seed, scratch),
        },
        lambda rec: f"{rec['independent']['seconds']:.0f} s",
    )


def run_even(seeds: list[int], out: Path) -> None:
    """Append the even paired run (``EVEN``) per seed not yet in ``out``."""
    _append_per_seed(
        seeds,
        out,
        lambda seed, scratch: {
            "settings": EVEN,
            "paired": paired_record(seed, scratch, EVEN),
        },
        lambda rec: f"{rec['paired']['seconds']:.0f} s",
    )


def _by_seed(path: Path) -> dict[int, dict[str, Any]]:
    """A results file's records by seed (a seed twice: the first)."""
    by_seed: dict[int, dict[str, Any]] = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            by_seed.setdefault(rec["seed"], rec)
    return by_seed


def summary(
    results: Path, even: Path | None = None, independent: Path | None = None
) -> tuple[dict[str, Any], str]:
    """The spread, the discordant share and the gate's outcomes, as figures and text.

    The independent runs' spread pools those of ``results`` with the seeds
    ``independent`` adds (a seed in both: ``results``'s).
    """
    recs = list(_by_seed(results).values())
    singles = (_by_seed(independent) if independent is not None else {}) | {
        r["seed"]: r for r in recs
    }
    paired = np.array([r["paired"]["difference"]["value"] for r in recs])
    indep = np.array(
        [r["independent"]["b"] - r["independent"]["a"] for r in singles.values()]
    )
    outcomes = [r["paired"]["outcome"] for r in recs]
    row = {
        "seeds": len(recs),
        "independent_seeds": len(singles),
        "r": float(np.mean([r["paired"]["r"] for r in recs])),
        "p_a": float(np.mean([r["paired"]["a"]["value"] for r in recs])),
        "p_b": float(np.mean([r["paired"]["b"]["value"] for r in recs])),
        "spread_paired": float(paired.std(ddof=1)),
        "spread_independent": float(indep.std(ddof=1)),
        "mean_difference_paired": float(paired.mean()),
        "mean_difference_independent": float(indep.mean()),
        "rollouts_paired": float(np.mean([2 * r["paired"]["n_evals"] for r in recs])),
        "rollouts_independent": float(
            np.mean([r["independent"]["n_evals"] for r in singles.values()])
        ),
        "outcomes": {o: outcomes.count(o) for o in ("pass", "fail", "inconclusive")},
        "caution": sum(r["paired"]["trust"] != "ok" for r in recs),
    }
    row["narrower_by"] = row["spread_independent"] / row["spread_paired"]
    lines = [
        "| pair | seeds | r | mean p_A | mean p_B | spread of p_B - p_A: paired, "
        "default | independent | independent / paired | rollouts: paired (both "
        "egos) | independent | gate at 1.0: pass / fail / inconclusive |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
        f"| `{SCENARIO}`, lidar ego / range x 1.3 | {row['seeds']} (independent: "
        f"{row['independent_seeds']}) "
        f"| {row['r']:.2f} | {row['p_a']:.3g} | {row['p_b']:.3g} "
        f"| {row['spread_paired']:.3g} | {row['spread_independent']:.3g} "
        f"| {row['narrower_by']:.2f} | {row['rollouts_paired']:,.0f} "
        f"| {row['rollouts_independent']:,.0f} "
        f"| {row['outcomes']['pass']} / {row['outcomes']['fail']} / "
        f"{row['outcomes']['inconclusive']} |",
    ]
    evens = list(_by_seed(even).values()) if even is not None else []
    if len(evens) > 1:
        spread = float(
            np.std([r["paired"]["difference"]["value"] for r in evens], ddof=1)
        )
        row |= {
            "even_seeds": len(evens),
            "spread_even": spread,
            "narrower_by_even": row["spread_independent"] / spread,
            "rollouts_even": float(
                np.mean([2 * r["paired"]["n_evals"] for r in evens])
            ),
        }
        lines += [
            "",
            "At equal rollouts (the even paired runs, `run-even`):",
            "",
            "| pair | seeds: even / independent | spread of p_B - p_A: paired, "
            "even | independent | independent / paired | rollouts: paired "
            "| independent |",
            "|---|---|---:|---:|---:|---:|---:|",
            f"| `{SCENARIO}`, lidar ego / range x 1.3 | {len(evens)} / "
            f"{row['independent_seeds']} "
            f"| {spread:.3g} | {row['spread_independent']:.3g} "
            f"| {row['narrower_by_even']:.2f} | {row['rollouts_even']:,.0f} "
            f"| {row['rollouts_independent']:,.0f} |",
        ]
    return row, "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command line: ``run``, ``run-independent``, ``run-even`` or ``table``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--seeds", default="0-49")
    r.add_argument("--out", type=Path, default=DEFAULT_OUT)
    r.add_argument("--reverse", action="store_true", help="the seeds downwards")
    i = sub.add_parser("run-independent")
    i.add_argument("--seeds", default="0-49")
    i.add_argument("--out", type=Path, default=INDEPENDENT_OUT)
    i.add_argument("--reverse", action="store_true", help="the seeds downwards")
    e = sub.add_parser("run-even")
    e.add_argument("--seeds", default="0-49")
    e.add_argument("--out", type=Path, default=EVEN_OUT)
    t = sub.add_parser("table")
    t.add_argument("--results", type=Path, default=DEFAULT_OUT)
    t.add_argument("--even", type=Path, default=EVEN_OUT)
    t.add_argument("--independent", type=Path, default=INDEPENDENT_OUT)
    t.add_argument("--md", type=Path)
    t.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.command == "run":
        seeds = parse_seeds(args.seeds)
        run(seeds[::-1] if args.reverse else seeds, args.out)
        return
    if args.command == "run-independent":
        seeds = parse_seeds(args.seeds)
        run_independent(seeds[::-1] if args.reverse else seeds, args.out)
        return
    if args.command == "run-even":
        run_even(parse_seeds(args.seeds), args.out)
        return
    row, md = summary(args.results, args.even, args.independent)
    print(md)
    if args.md:
        args.md.write_text(md + "\n")
    if args.json:
        args.json.write_text(json.dumps(row, indent=1) + "\n")


if __name__ == "__main__":
    main()
