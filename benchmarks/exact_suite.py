"""The estimators on problems with exact answers, nobody tuned for (issue 46, item 4).

Runs every (problem, method, seed) of the suite (``avrisk.testing.suite``:
k half-space regions of unequal mass, plateaus of ``f``, Beta blocks and the
``otbenchmark`` reliability problems, each with ``p`` computed independently)
at ONE setting for the whole suite, and tabulates how honest each method's
answers are::

    OMP_NUM_THREADS=1 python benchmarks/exact_suite.py run \\
        [--problems RP110,kregions_k5_d50_p1e-06] [--methods splitting_is,ot_ce] \\
        [--seeds 0-49] [--jobs 1] [--out benchmarks/results/exact_suite/runs.jsonl]
    python benchmarks/exact_suite.py table [--results A.jsonl B.jsonl:ce,mixture] \\
        [--md T.md] \\
        [--json T.json]
    python benchmarks/exact_suite.py settings

The setting: each engine method at the command line's defaults (``avrisk run``:
the estimator's own settings, ``n_iter = 20`` for cross-entropy), with its
sample counts (``n_particles``, ``n_per_iter``, ``n_final``) scaled by one
factor so that its planned budget (:meth:`Estimator.budget`, an upper bound
for splitting, every diagnostic included) is at most ``SUITE_BUDGET = 1e5``
calls of ``f``; for ``splitting_is`` the plan without regrowth, with the cap
``max_calls = SUITE_BUDGET`` on its regrowths (a replicate that ran out of
levels runs again only while the whole run's bound stays within the cap).
OpenTURNS's ``SubsetSampling`` and
``StandardSpaceCrossEntropyImportanceSampling`` (defaults, probability 0.1 per
level / quantile level 0.1) run in the base's standard-normal space with
``OT_PER_STEP`` samples per level or iteration, stopped with an error past
``SUITE_BUDGET`` calls. ``settings`` prints all of it.

``run --set NAME=VALUE`` runs a variant, its sample counts scaled to the same
budget; with ``--on-top`` it keeps the default's sample counts and adds its own
calls, so that its runs are the default's bit for bit wherever it changes nothing
(a paired comparison, not one of two random streams).

``run`` appends one JSON line per run to ``--out`` and skips runs already there
(same problem, method, seed and settings), so an interrupted sweep goes on where
it stopped. A run that raises is a result (its error's first line recorded),
not a crash of the sweep.

``table`` prints, per (problem, method), as markdown (and writes JSON):

* the exact ``p`` and how many runs finished / raised (with the first error);
* coverage of the 95% interval: a run covers when ``p`` lies within its
  interval widened by ``1.96`` times the reference's own standard error
  (zero for closed forms and quadratures);
* mean relative bias +- its standard error, and relative RMSE, over the runs
  that finished;
* mean calls of ``f``;
* gross misses: the interval misses ``p`` and the estimate is off by more than
  2 times either way; with how many of those the engine's trust rule
  (``avrisk.rare.trust.estimate_trust``, the CLI's) labelled ``ok``;
* the share of covering runs labelled ``caution`` (a label that cries wolf),
  bound-only answers left out of it;
* bound-only answers (no hit: the interval is an upper bound), apart.

OpenTURNS's runs have no trust label (``n/a``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import traceback
import warnings
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "exact_suite" / "runs.jsonl"

#: Most calls of f a run may make, every diagnostic included.
SUITE_BUDGET = 100_000
#: Settings of an engine estimator that count samples (scaled to the budget).
COUNT_SETTINGS = ("n_particles", "n_per_iter", "n_final")
#: OpenTURNS: samples per subset level / cross-entropy iteration.
OT_PER_STEP = 8_000
#: OpenTURNS: samples evaluated together (SubsetSampling's chains take one
#: step per block: a block of all ``OT_PER_STEP`` would leave them unmixed).
OT_BLOCK = 100
OT_METHODS = ("ot_subset", "ot_ce")
DEFAULT_METHODS = ("splitting_is", "splitting", "mixture", "ce", *OT_METHODS)
LABELS = {
    "splitting_is": "splitting_is",
    "splitting": "subset_simulation",
    "mixture": "mixture_ce",
    "ce": "cross_entropy",
    "defensive": "defensive_ce",
    "naive": "naive_mc",
    "ot_subset": "OT SubsetSampling",
    "ot_ce": "OT standard-space CE",
}


def _on_top(
    method: str, default: dict[str, Any], changed: dict[str, Any]
) -> dict[str, Any]:
    """``default`` with ``changed`` set, ``max_calls`` raised by what they add."""
    from avrisk.rare.estimator import get_estimator, planned_budget

    if "max_calls" not in default:
        return {**default, **changed}
    uncapped = {k: v for k, v in default.items() if k != "max_calls"}
    extra = planned_budget(get_estimator(method, **uncapped, **changed)) - (
        planned_budget(get_estimator(method, **uncapped))
    )
    return {**default, **changed, "max_calls": default["max_calls"] + max(0, extra)}


class BudgetExceeded(RuntimeError):
    """A method asked for more calls of f than the suite's budget."""


def suite_settings(
    method: str, changed: dict[str, Any] | None = None, on_top: bool = False
) -> dict[str, Any]:
    """The suite's one setting of ``method`` (see the module docstring).

    ``changed``: settings of the method set otherwise before the sample counts
    are scaled to the budget (a variant measured beside the default). With
    ``on_top``, set after them instead: the variant runs at the default's
    sample counts, its own calls on top of the budget (``max_calls`` raised to
    its bound), so that where it changes nothing its runs are the default's
    bit for bit and where it does, the difference is its own, not that of
    other sample counts drawing other random numbers.
    """
    if method in OT_METHODS:
        return {"per_step": OT_PER_STEP, "block": OT_BLOCK, "max_calls": SUITE_BUDGET}
    if on_top and changed:
        return _on_top(method, suite_settings(method), changed)
    from avrisk.cli.estimator_options import CLI_DEFAULTS
    from avrisk.rare.estimator import estimator_class, get_estimator, planned_budget

    fields = estimator_class(method).Settings.model_fields
    base = {k: v for k, v in CLI_DEFAULTS.items() if k in fields} | (changed or {})
    default = get_estimator(method, **base)
    scale = SUITE_BUDGET / planned_budget(default)  # the plan without regrowth
    counts = {
        k: max(100, int(getattr(default.settings, k) * scale) // 100 * 100)
        for k in COUNT_SETTINGS
        if k in fields
    }
    while planned_budget(get_estimator(method, **base, **counts)) > SUITE_BUDGET:
        counts = {k: v - 100 for k, v in counts.items()}
    cap = {"max_calls": SUITE_BUDGET} if "max_calls" in fields else {}
    return {**base, **counts, **cap}


class _Counted:
    """``f`` that counts its calls and refuses to exceed ``limit``."""

    def __init__(self, f: Any, limit: int | None = None) -> None:
        self.f, self.limit, self.calls = f, limit, 0

    def __call__(self, x: np.ndarray) -> np.ndarray:
        self.calls += len(x)
        if self.limit is not None and self.calls > self.limit:
            raise BudgetExceeded(f"more than {self.limit:,} calls of f")
        return self.f(x)


def _run_engine(problem: Any, method: str, seed: int, settings: dict) -> dict:
    from avrisk.rare.estimation_context import EstimationContext
    from avrisk.rare.estimator import (
        estimator_class,
        get_estimator,
        run_estimator,
    )
    from avrisk.rare.problem import RareEventProblem
    from avrisk.rare.trust import estimate_trust

    f = _Counted(problem.f)
    estimator = get_estimator(method, **settings)
    rare = RareEventProblem(problem.base, f, problem.gamma)
    estimate = run_estimator(estimator, rare, EstimationContext(seed=seed))
    as_dict = estimate.to_dict()
    main_dict = next(g for g in as_dict["by_gamma"] if g["gamma"] == estimate.gamma)
    trust = estimate_trust(estimator_class(method), as_dict, main_dict)
    main = estimate.main
    return {
        "p": estimate.p,
        "stderr": estimate.stderr,
        "ci": list(estimate.ci),
        "n_calls": f.calls,
        "n_evals": estimate.n_evals,
        "n_hits": estimate.n_hits,
        "ess": estimate.ess,
        "pareto_k": getattr(main, "pareto_k", None),
        "trust": trust.word,
        "reasons": list(trust.reasons),
        # which of its estimates answered, where a method has two
        "answer": (estimate.details or {}).get("answer"),
        # the check by rays where X is low-dimensional (avrisk.rare.directional_audit)
        "rays": (estimate.details or {}).get("directional"),
        # whether splitting_is's proposal fitted variances too
        "fitted_variances": (estimate.details or {}).get("fitted_variances"),
    }


def _run_openturns(problem: Any, method: str, seed: int, settings: dict) -> dict:
    import openturns as ot

    base = problem.base
    f = _Counted(problem.f, settings["max_calls"])

    def g(u: Any) -> np.ndarray:
        x = base.from_standard_normal(np.asarray(u, dtype=float))
        return np.asarray(f(x), dtype=float)[:, None]

    ot.TBB.SetThreadsNumber(1)  # one core, as the engine's runs
    ot.RandomGenerator.SetSeed(seed)
    function = ot.PythonFunction(base.dim, 1, func_sample=g)
    vector = ot.CompositeRandomVector(function, ot.RandomVector(ot.Normal(base.dim)))
    event = ot.ThresholdEvent(vector, ot.LessOrEqual(), problem.gamma)
    if method == "ot_subset":
        algo = ot.SubsetSampling(event)
    else:
        algo = ot.StandardSpaceCrossEntropyImportanceSampling(event)
    # outer x block samples a step; SubsetSampling moves each chain one
    # Metropolis-Hastings step per outer iteration, so the blocks stay small
    algo.setMaximumOuterSampling(settings["per_step"] // settings["block"])
    algo.setBlockSize(settings["block"])
    algo.run()
    result = algo.getResult()
    p = result.getProbabilityEstimate()
    stderr = result.getStandardDeviation()
    return {
        "p": p,
        "stderr": stderr,
        "ci": [max(p - 1.96 * stderr, 0.0), p + 1.96 * stderr],
        "n_calls": f.calls,
        "n_evals": f.calls,
        "n_hits": None,
        "ess": None,
        "pareto_k": None,
        "trust": None,
        "reasons": [],
    }


_PROBLEMS: dict[str, Any] = {}


def run_one(problem_name: str, method: str, seed: int, settings: dict) -> dict:
    """One run as a JSON-ready record; an exception is recorded, not raised."""
    from avrisk.testing.suite import suite_problem

    if problem_name not in _PROBLEMS:
        _PROBLEMS[problem_name] = suite_problem(problem_name)
    problem = _PROBLEMS[problem_name]
    record = {
        "problem": problem_name,
        "method": method,
        "seed": seed,
        "settings": settings,
        "p_exact": problem.p_exact,
        "p_rel_error": problem.p_rel_error,
        "dim": problem.base.dim,
    }
    start = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            runner = _run_openturns if method in OT_METHODS else _run_engine
            record.update(runner(problem, method, seed, settings))
            record["error"] = None
        except Exception as err:  # a run that raises is a result
            text = str(err).strip().splitlines()
            record["error"] = f"{type(err).__name__}: {text[0] if text else ''}"
            record["traceback_tail"] = traceback.format_exc().splitlines()[-3:]
    record["cpu_s"] = time.process_time() - start
    record["warnings"] = dict(Counter(type(w.message).__name__ for w in caught))
    return record


def _assignment(text: str) -> tuple[str, Any]:
    """``("n_moves", 3)`` from ``"n_moves=3"`` (the value read as YAML)."""
    import yaml

    name, sep, value = text.partition("=")
    if not sep:
        raise SystemExit(f"--set takes NAME=VALUE; got {text!r}")
    return name.strip(), yaml.safe_load(value)


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        out.extend(range(int(first), int(last or first) + 1))
    return out


def _key(record: dict) -> tuple:
    return (
        record["problem"],
        record["method"],
        record["seed"],
        json.dumps(record["settings"], sort_keys=True),
    )


def _read(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line]


def _commit() -> str:
    """The short git commit of the avrisk checkout the run imports, or "unknown"."""
    from avrisk.pipeline.provenance import code_version

    return (code_version()["git_commit"] or "unknown")[:7]


def run(args: argparse.Namespace) -> None:
    """Run the (problem, method, seed) triples not yet in ``args.out``."""
    from avrisk.testing.suite import SUITE

    problems = args.problems.split(",") if args.problems else list(SUITE)
    methods = args.methods.split(",") if args.methods else list(DEFAULT_METHODS)
    changed = dict(_assignment(text) for text in args.set)
    settings = {m: suite_settings(m, changed, args.on_top) for m in methods}
    done = {_key(r) for r in _read(args.out)}
    tasks = [
        (problem, method, seed, settings[method])
        for seed in _seeds(args.seeds)
        for problem in problems
        for method in methods
        if (problem, method, seed, json.dumps(settings[method], sort_keys=True))
        not in done
    ]
    print(f"{len(tasks)} runs to do ({len(done)} done) -> {args.out}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    commit = _commit()
    with args.out.open("a") as out:

        def write(record: dict) -> None:
            record["commit"] = commit
            out.write(json.dumps(record) + "\n")
            out.flush()
            status = (
                record["error"] or f"p/p_exact={record['p'] / record['p_exact']:.3g}"
            )
            print(
                f"{record['problem']} {record['method']} seed {record['seed']}: "
                f"{status} ({record['cpu_s']:.1f} s)",
                flush=True,
            )

        if args.jobs <= 1:
            for task in tasks:
                write(run_one(*task))
            return
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(run_one, *task) for task in tasks]
            for future in as_completed(futures):
                write(future.result())


def _covers(r: dict) -> bool:
    lo, hi = r["ci"]
    p, est = r["p_exact"], r["p"]
    ref = 1.96 * p * r.get("p_rel_error", 0.0)
    below = math.hypot(est - lo, ref)
    above = math.hypot(hi - est, ref)
    return est - below <= p <= est + above


def _gross(r: dict) -> bool:
    ratio = r["p"] / r["p_exact"]
    return not _covers(r) and (ratio > 2 or ratio < 0.5)


def summarize(records: list[dict]) -> list[dict]:
    """One row per (problem, method) and a pooled row per method."""
    latest: dict[tuple, dict] = {}
    for r in records:
        latest[_key(r)] = r
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in latest.values():
        groups[(r["problem"], r["method"])].append(r)
    rows = [_row(problem, method, runs) for (problem, method), runs in groups.items()]
    order = {m: i for i, m in enumerate(LABELS)}
    rows.sort(key=lambda row: (row["problem"], order.get(row["method"], 99)))
    for method in sorted({row["method"] for row in rows}, key=lambda m: order[m]):
        runs = [r for (_, m), rs in groups.items() if m == method for r in rs]
        pooled = _row("(pooled)", method, runs)
        rows.append(pooled)
    return rows


def _row(problem: str, method: str, runs: list[dict]) -> dict:
    finished = [r for r in runs if r["error"] is None and r["p"] is not None]
    raised = [r for r in runs if r["error"] is not None]
    covers = [r for r in finished if _covers(r)]
    gross = [r for r in finished if _gross(r)]
    labelled = [r for r in finished if r["trust"] is not None]
    rel = np.array([r["p"] / r["p_exact"] - 1 for r in finished])
    n = len(finished)
    errors = Counter(r["error"] for r in raised)
    return {
        "problem": problem,
        "method": method,
        "p_exact": runs[0]["p_exact"] if problem != "(pooled)" else None,
        "runs": len(runs),
        "finished": n,
        "raised": len(raised),
        "errors": dict(errors.most_common()),
        "covered": len(covers),
        "coverage": len(covers) / n if n else None,
        "bias": float(rel.mean()) if n else None,
        "bias_se": float(rel.std(ddof=1) / math.sqrt(n)) if n > 1 else None,
        "rel_rmse": float(np.sqrt((rel**2).mean())) if n else None,
        "mean_calls": float(np.mean([r["n_calls"] for r in finished])) if n else None,
        "gross": len(gross),
        "gross_ok": sum(r["trust"] == "ok" for r in gross) if labelled else None,
        # bound-only answers (no hit) are counted apart, not as crying wolf
        "covering_answered": sum(r.get("n_hits") != 0 for r in covers),
        "covering_caution": sum(
            r["trust"] == "caution" and r.get("n_hits") != 0 for r in covers
        )
        if labelled
        else None,
        "bound_only": sum(r.get("n_hits") == 0 for r in finished),
        "cpu_s": float(sum(r["cpu_s"] for r in runs)),
    }


def _fmt(row: dict) -> str:
    def pct(x: float | None) -> str:
        return "" if x is None else f"{x:+.1%}"

    n = row["finished"]
    cov = f"{row['covered']}/{n}" if n else "-"
    bias = (
        f"{pct(row['bias'])} +- {row['bias_se']:.1%}"
        if row["bias_se"] is not None
        else pct(row["bias"])
    )
    rmse = "" if row["rel_rmse"] is None else f"{row['rel_rmse']:.3g}"
    calls = "" if row["mean_calls"] is None else f"{row['mean_calls']:,.0f}"
    gross = str(row["gross"])
    if row["gross_ok"] is not None:
        gross += f" ({row['gross_ok']} ok)"
    caution = (
        "n/a"
        if row["covering_caution"] is None
        else f"{row['covering_caution']}/{row['covering_answered']}"
    )
    raised = str(row["raised"])
    if row["errors"]:
        first = next(iter(row["errors"]))
        raised += f": {first[:70]}"
    p = "" if row["p_exact"] is None else f"{row['p_exact']:.4g}"
    return (
        f"| {row['problem']} | {p} | {LABELS.get(row['method'], row['method'])} | "
        f"{cov} | {bias} | {rmse} | {calls} | {gross} | {caution} | "
        f"{row['bound_only']} | {raised} |"
    )


HEADER = (
    "| problem | exact p | method | covered | bias +- se | rel. RMSE | mean calls "
    "| gross misses (labelled ok) | covering labelled caution | bound only "
    "| raised |\n|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|"
)


def _results(specs: list[str]) -> list[dict]:
    """The records of ``FILE`` or ``FILE:METHOD,METHOD`` specs, in order.

    A method's runs come from the first spec that names it (or names no
    method and holds it): the latest runs of a changed method beside the
    earlier ones of the others.
    """
    records: list[dict] = []
    taken: set[str] = set()
    for spec in specs:
        path, _, names = spec.partition(":")
        wanted = set(names.split(",")) if names else None
        found = [
            r
            for r in _read(Path(path))
            if r["method"] not in taken and (wanted is None or r["method"] in wanted)
        ]
        records.extend(found)
        taken |= {r["method"] for r in found}
    return records


def _recorded_settings(records: list[dict], method: str) -> str:
    """The settings ``method``'s runs recorded, each once (backquoted JSON)."""
    seen = dict.fromkeys(
        json.dumps(r["settings"], sort_keys=True)
        for r in records
        if r["method"] == method
    )
    return "; ".join(f"`{text}`" for text in seen)


def table(args: argparse.Namespace) -> None:
    """Print (and write) the table of ``args.results``."""
    records = _results(args.results)
    rows = summarize(records)
    methods = sorted(
        {r["method"] for r in records}, key=lambda m: list(LABELS).index(m)
    )
    seeds = sorted({r["seed"] for r in records})
    cpu = sum(r["cpu_s"] for r in records)
    lines = [
        f"{len(records)} runs, seeds {seeds[0]}-{seeds[-1]}, {cpu / 60:.1f} CPU-min, "
        f"commit(s) {', '.join(sorted({r.get('commit', '?') for r in records}))}.",
        "",
        "Settings (one for the whole suite, at most "
        f"{SUITE_BUDGET:,} calls of f a run):",
        "",
        *(f"- {LABELS.get(m, m)}: {_recorded_settings(records, m)}" for m in methods),
        "",
        HEADER,
        *(_fmt(row) for row in rows),
    ]
    text = "\n".join(lines)
    print(text)
    if args.md:
        args.md.write_text(text + "\n")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


def settings_command(args: argparse.Namespace) -> None:
    """Print the suite's one setting of every method."""
    from avrisk.rare.estimator import get_estimator

    for method in LABELS:
        s = suite_settings(method)
        plan = (
            f"at most {s['max_calls']:,} calls"
            if method in OT_METHODS
            else get_estimator(method, **s).describe()
        )
        print(f"{LABELS[method]} ({method}): {json.dumps(s)}  [{plan}]")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the sweep (resumable)")
    r.add_argument("--problems", default="", help="comma-separated (default: SUITE)")
    r.add_argument("--methods", default="", help="comma-separated")
    r.add_argument("--seeds", default="0-49", help="e.g. 0-49 or 0-4,10")
    r.add_argument("--jobs", type=int, default=1, help="processes")
    r.add_argument("--out", type=Path, default=DEFAULT_OUT)
    r.add_argument(
        "--set",
        action="append",
        default=[],
        help="NAME=VALUE: a setting of every method run changed (a variant)",
    )
    r.add_argument(
        "--on-top",
        action="store_true",
        help="the --set variant at the default's sample counts, its calls on top",
    )
    r.set_defaults(func=run)
    t = sub.add_parser("table", help="tabulate a results file")
    t.add_argument(
        "--results",
        nargs="+",
        default=[str(DEFAULT_OUT)],
        help="FILE or FILE:METHOD,METHOD (runs of a method from the first that "
        "holds it)",
    )
    t.add_argument("--md", type=Path, default=None, help="write the markdown here")
    t.add_argument("--json", type=Path, default=None, help="write the rows here")
    t.set_defaults(func=table)
    s = sub.add_parser("settings", help="print the suite's settings")
    s.set_defaults(func=settings_command)
    args = parser.parse_args(argv)
    args.func(args)


if __name__ == "__main__":
    sys.exit(main())
