"""Paired comparison of two versions on a scenario: spread and gate (issue 45).

The bundled pair's rows of the efficiency table (``examples/ab_lidar``: the
shipped lidar ego ``A`` and its variant ``B`` whose lidar reads every range
30% long) and the gate's outcomes at the CLI's default budget. Per seed, each
command into a file of its own:

* ``run-paired``: the paired run, as ``avrisk ab`` makes it
  (:func:`avrisk.api.compare_egos`, its default settings ``PAIRED_DEFAULTS``:
  ``splitting_is`` on ``min(f_A, f_B)``), its estimates of ``p_A``, ``p_B``,
  ``p_B - p_A`` and ``p_B / p_A`` with their intervals, the discordant share,
  its label and the gate's outcome at ``MAX_RATIO``;
* ``run-single``: two default single-version ``splitting_is`` runs
  (:func:`avrisk.api.estimate`, ``SINGLE``), one per ego, on seeds of their
  own (``SINGLE_SEED + 2 seed`` and ``+ 1``). Every draw of the paired run is
  simulated with both egos, so the two simulate about as many rollouts as
  it: the comparison at the default budget;
* ``run-even`` and ``run-independent``: the same comparison at half those
  budgets, a paired run at half ``PAIRED_DEFAULTS`` (``EVEN``) against two
  runs at half ``SINGLE`` (``INDEPENDENT``, seeds ``INDEPENDENT_SEED + 2
  seed`` and ``+ 1``);
* ``run``: the default paired run and the runs at half ``SINGLE`` together
  (into the paired runs' file).

::

    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-paired \\
        [--seeds 0-49] [--reverse] [--out ...lidar_pair_final_heavy.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-single \\
        [--seeds 0-49] [--out benchmarks/results/ab/lidar_pair_single.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-even \\
        [--seeds 0-49] [--out ...lidar_pair_even_final_heavy.jsonl]
    OMP_NUM_THREADS=1 nice -n 19 python benchmarks/ab_scenario.py run-independent \\
        [--seeds 0-49] [--out benchmarks/results/ab/lidar_pair_independent.jsonl]
    python benchmarks/ab_scenario.py table [--results ...] [--single ...] \\
        [--even ...] [--independent ...] [--md T.md] [--json T.json]

Each command appends one JSON line per seed and skips seeds already there, so an
interrupted sweep goes on (each seed's run directories are temporary); a
second process may go down the seeds into the same file (``--reverse``). No
exact answer is known here, so ``table`` reports what needs none: the spread
(standard deviation over seeds) of the paired difference against that of the
two independent runs' difference at about the same rollouts, their ratio
(what the analytic pairs' table of ``ab_coverage.py`` reports against
``r``), the paired runs labelled caution, the mean discordant share ``r``,
the gate's outcomes, and the rollouts each way. The runs before
``PAIRED_DEFAULTS`` (``lidar_pair.jsonl``, ``lidar_pair_even*.jsonl`` but
``_final_heavy``) are at earlier settings.
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
from avrisk.testing.ab_budgets import EVEN, INDEPENDENT, PAIRED, SINGLE  # noqa: E402

SCENARIO = "highway_default"
EGOS = {
    which: ROOT / "examples" / "ab_lidar" / name
    for which, name in (("a", "lidar_ego.yaml"), ("b", "lidar_ego_degraded.yaml"))
}
RESULTS = ROOT / "benchmarks" / "results" / "ab"
EVEN_OUT = RESULTS / "lidar_pair_even_final_heavy.jsonl"
INDEPENDENT_OUT = RESULTS / "lidar_pair_independent.jsonl"
SINGLE_OUT = RESULTS / "lidar_pair_single.jsonl"
PAIRED_OUT = RESULTS / "lidar_pair_final_heavy.jsonl"
#: Offset of the independent runs' seeds, so none shares a paired run's draws.
INDEPENDENT_SEED = 1_000_000
#: Offset of the default single runs' seeds, so none shares another run's draws.
SINGLE_SEED = 2_000_000
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


def independent_record(
    seed: int,
    scratch: Path,
    settings: dict[str, int] = INDEPENDENT,
    first_seed: int = INDEPENDENT_SEED,
) -> dict[str, Any]:
    """Two independent runs at ``settings``, one per ego: estimates and rollouts.

    Their seeds are ``first_seed + 2 seed`` (ego A) and ``+ 1`` (ego B).
    """
    start = time.perf_counter()
    runs = {}
    for offset, which in enumerate(("a", "b")):
        result = estimate(
            SCENARIO,
            ego=_ego(which),
            out=scratch / which,
            seed=first_seed + 2 * seed + offset,
            failures=0,
            **settings,
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


def run_paired(seeds: list[int], out: Path) -> None:
    """Append the default paired run alone per seed not yet in ``out``."""
    _append_per_seed(
        seeds,
        out,
        lambda seed, scratch: {
            "egos": {k: str(v.relative_to(ROOT)) for k, v in EGOS.items()},
            "settings": PAIRED,
            "paired": paired_record(seed, scratch),
        },
        lambda rec: (
            f"{rec['paired']['outcome']}, ratio {rec['paired']['ratio']['value']:.3g}, "
            f"{rec['paired']['trust']}, {rec['paired']['seconds']:.0f} s"
        ),
    )


def run_single(seeds: list[int], out: Path) -> None:
    """Append two default single-version runs (``SINGLE``) per seed not in ``out``.

    Together they simulate about as many rollouts as the default paired run
    (whose draws each take both egos): the comparison at the default budget.
    """
    _append_per_seed(
        seeds,
        out,
        lambda seed, scratch: {
            "single_settings": SINGLE,
            "single": independent_record(seed, scratch, SINGLE, SINGLE_SEED),
        },
        lambda rec: f"{rec['single']['seconds']:.0f} s",
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


def _spread(values: list[float]) -> float:
    """Standard deviation over seeds (NaN below two)."""
    return float(np.std(values, ddof=1)) if len(values) > 1 else math.nan


def _comparison(
    name: str, paired: list[dict[str, Any]], independent: list[dict[str, Any]]
) -> dict[str, Any]:
    """One row: a paired run's spread of ``p_B - p_A`` against two runs' one.

    ``paired``: records' ``paired`` parts; ``independent``: pairs of runs
    (``a``, ``b``, ``n_evals``).
    """
    spread_paired = _spread([r["difference"]["value"] for r in paired])
    spread_independent = _spread([r["b"] - r["a"] for r in independent])
    return {
        "comparison": name,
        "seeds_paired": len(paired),
        "seeds_independent": len(independent),
        "spread_paired": spread_paired,
        "spread_independent": spread_independent,
        "narrower_by": spread_independent / spread_paired,
        "caution_paired": sum(r["trust"] != "ok" for r in paired),
        "rollouts_paired": float(np.mean([2 * r["n_evals"] for r in paired])),
        "rollouts_independent": float(np.mean([r["n_evals"] for r in independent])),
    }


def summary(
    results: Path,
    even: Path | None = None,
    independent: Path | None = None,
    single: Path | None = None,
) -> tuple[dict[str, Any], str]:
    """The spreads, the discordant share and the gate's outcomes, as figures and text.

    ``results``: default paired runs (``run`` or ``run-paired``); their
    discordant share, gate outcomes and labels head the table. Each row sets
    a paired run's spread against two independent runs' at about the same
    rollouts: the default paired run against two default single runs
    (``single``), and the even paired run (``even``) against the runs at
    half those settings (``independent``, pooled with any in ``results``; a
    seed in both: ``results``'s). A row needs two seeds a side.
    """
    recs = list(_by_seed(results).values())
    paired = [r["paired"] for r in recs]
    halves = (_by_seed(independent) if independent is not None else {}) | {
        r["seed"]: r for r in recs if "independent" in r
    }
    outcomes = [r["outcome"] for r in paired]
    head = {
        "seeds": len(paired),
        "r": float(np.mean([r["r"] for r in paired])),
        "p_a": float(np.mean([r["a"]["value"] for r in paired])),
        "p_b": float(np.mean([r["b"]["value"] for r in paired])),
        "outcomes": {o: outcomes.count(o) for o in ("pass", "fail", "inconclusive")},
        "caution": sum(r["trust"] != "ok" for r in paired),
    }
    rows = []
    singles = list(_by_seed(single).values()) if single is not None else []
    if len(paired) > 1 and len(singles) > 1:
        rows.append(
            _comparison(
                "default paired / two default single runs",
                paired,
                [r["single"] for r in singles],
            )
        )
    evens = [r["paired"] for r in _by_seed(even).values()] if even else []
    if len(evens) > 1 and len(halves) > 1:
        rows.append(
            _comparison(
                "even paired / two runs at half the default",
                evens,
                [r["independent"] for r in halves.values()],
            )
        )
    lines = [
        f"`{SCENARIO}`, lidar ego / range x 1.3; default paired runs: "
        f"{head['seeds']} seeds, r = {head['r']:.2f}, mean p_A {head['p_a']:.3g}, "
        f"mean p_B {head['p_b']:.3g}, gate at {MAX_RATIO:g}: pass / fail / "
        f"inconclusive {head['outcomes']['pass']} / {head['outcomes']['fail']} / "
        f"{head['outcomes']['inconclusive']}, labelled caution {head['caution']}.",
        "",
        "| comparison | seeds: paired / independent | spread of p_B - p_A: paired "
        "| independent | independent / paired | paired labelled caution "
        "| rollouts: paired (both egos) | independent |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    lines += [
        f"| {r['comparison']} | {r['seeds_paired']} / {r['seeds_independent']} "
        f"| {r['spread_paired']:.3g} | {r['spread_independent']:.3g} "
        f"| {r['narrower_by']:.2f} | {r['caution_paired']} "
        f"| {r['rollouts_paired']:,.0f} | {r['rollouts_independent']:,.0f} |"
        for r in rows
    ]
    return {**head, "comparisons": rows}, "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command line: ``run``, ``run-paired``, ``run-single``, ``run-independent``,
    ``run-even`` or ``table``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    runs = {
        "run": (run, PAIRED_OUT),
        "run-paired": (run_paired, PAIRED_OUT),
        "run-single": (run_single, SINGLE_OUT),
        "run-independent": (run_independent, INDEPENDENT_OUT),
        "run-even": (run_even, EVEN_OUT),
    }
    for name, (_, out) in runs.items():
        r = sub.add_parser(name)
        r.add_argument("--seeds", default="0-49")
        r.add_argument("--out", type=Path, default=out)
        r.add_argument("--reverse", action="store_true", help="the seeds downwards")
    t = sub.add_parser("table")
    t.add_argument("--results", type=Path, default=PAIRED_OUT)
    t.add_argument("--even", type=Path, default=EVEN_OUT)
    t.add_argument("--independent", type=Path, default=INDEPENDENT_OUT)
    t.add_argument("--single", type=Path, default=SINGLE_OUT)
    t.add_argument("--md", type=Path)
    t.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.command in runs:
        seeds = parse_seeds(args.seeds)
        runs[args.command][0](seeds[::-1] if args.reverse else seeds, args.out)
        return
    row, md = summary(args.results, args.even, args.independent, args.single)
    print(md)
    if args.md:
        args.md.write_text(md + "\n")
    if args.json:
        args.json.write_text(json.dumps(row, indent=1) + "\n")


if __name__ == "__main__":
    main()
