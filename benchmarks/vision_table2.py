"""The paper's Table 2 on ``highway_vision``: CE, naive and splitting_is (issue 23).

The paper's vision experiment (O'Kelly et al. 2018, Table 2) at its budget: CE
with K = 20 iterations of N_k = 1,000 and a final 50,000 (70,000 rollouts),
naive Monte Carlo with 50,000, and, as the cross-check, ``splitting_is`` (this
project's best estimator) at about the same budget (4,000 particles per level
and a final 45,000: 61,000-97,000 rollouts, as its levels fall). Every run
targets gamma = 0.22 s (the paper's gamma_test 0.22-0.25 s) and reports 0.1,
0.2, 0.25 and 0.3 s beside it.

``run`` runs the three as ``avrisk run`` does (each a run directory under
``OUT/runs/`` with its report) and keeps each run's ``--json`` document as
``OUT/METHOD.json``; a vision rollout renders 101 frames, so run it on a GPU::

    python benchmarks/vision_table2.py run --device cuda --seed 1 \\
        --out benchmarks/results/vision_table2

``table`` also draws the paper's Fig. 4 (``OUT/fig4.png``): per threshold, the
ratio of rare events seen (hits of a method's final stage over the hits naive
Monte Carlo expects with as many rollouts, ``p_ref n``) and the ratio of
variances (naive's at the same budget, ``p_ref (1 - p_ref) / n``, over the
method's squared standard error) for CE and ``splitting_is``.

``table`` prints the runs beside a naive reference (``benchmarks/reference.py
highway_vision``) as Markdown: each estimate with its 95% interval, its
distance from the reference in combined standard errors, and whether its
interval, widened by the reference's own error, covers the reference
(``benchmarks/coverage.py``); then the failures by mechanism::

    python benchmarks/vision_table2.py table --out benchmarks/results/vision_table2 \\
        --reference benchmarks/results/references/highway_vision.json

The table refuses runs whose scenario or weights differ from the reference's.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

#: The paper's vision budget per method, as ``avrisk run`` options.
METHODS: dict[str, list[str]] = {
    "ce": ["--method", "ce", "--n-iter", "20", "--n-per-iter", "1000"]
    + ["--n-final", "50000"],
    "naive": ["--method", "naive", "--n-final", "50000"],
    "splitting_is": ["--method", "splitting_is", "--set", "n_particles=4000"]
    + ["--n-final", "45000"],
}
GAMMA, GAMMA_TEST = "0.22", "0.1,0.2,0.25,0.3"


def _coverage_module():
    """``benchmarks/coverage.py`` (the widened interval), loaded by path."""
    path = Path(__file__).with_name("coverage.py")
    spec = importlib.util.spec_from_file_location("avrisk_benchmark_coverage", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(args: argparse.Namespace) -> None:
    """Run each method once (``avrisk run ... --json``)."""
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.methods.split(","):
        command = [sys.executable, "-m", "avrisk", "run", "highway_vision"]
        command += METHODS[name] + ["--gamma", GAMMA, "--gamma-test", GAMMA_TEST]
        command += ["--seed", str(args.seed), "--device", args.device]
        command += ["--batch-size", str(args.batch_size), "--failures", "3"]
        command += ["--out", str(args.out / "runs" / name), "--json"]
        print(" ".join(command[1:]), file=sys.stderr, flush=True)
        with open(args.out / f"{name}.json", "w") as sink:
            subprocess.run(command, stdout=sink, check=True)


def table(args: argparse.Namespace) -> None:
    """Print the runs against the reference, as Markdown."""
    widened = _coverage_module().widened
    reference = json.loads(args.reference.read_text())
    ref_by_gamma = {g["gamma"]: g for g in reference["by_gamma"]}
    print(
        f"Reference: {reference['n']:,} naive rollouts, seed {reference['seed']} "
        f"({reference['provenance']['computed_with']['device']}).\n"
    )
    print(
        "| method | rollouts | wall [s] | gamma [s] | p | 95% CI | rel. se "
        "| reference | (p - ref) / combined se | covered (widened) | ESS "
        "| Pareto k |"
    )
    print("|---|---:|---:|---:|---:|---|---:|---:|---:|---|---:|---:|")
    mechanisms = {}
    for path in sorted(args.out.glob("*.json")):
        document = json.loads(path.read_text())
        (result,) = document["runs"]
        run_dir = args.out / "runs" / path.stem
        summary = json.loads((run_dir / "summary.json").read_text())
        if summary["provenance"]["defines_p"] != reference["provenance"]["defines_p"]:
            sys.exit(f"{path}: another scenario or other weights than the reference")
        wall = summary["timing"]["wall_time_s"]
        mechanisms[result["method"]] = result["mechanisms"]
        for g in result["by_gamma"]:
            ref = ref_by_gamma.get(g["gamma"])
            if ref is None:
                continue
            p, (lo, hi), se = g["p"], g["ci"], g["stderr"]
            low, high = widened(
                np.array([p]), np.array([lo]), np.array([hi]), ref["stderr"]
            )
            z = (p - ref["p"]) / math.hypot(se, ref["stderr"])
            covered = "yes" if low[0] <= ref["p"] <= high[0] else "**no**"
            k = "-" if g["pareto_k"] is None else f"{g['pareto_k']:.2f}"
            print(
                f"| {result['method']} | {result['n_rollouts']:,} | {wall:.0f} "
                f"| {g['gamma']:g} | {p:.3e} | [{lo:.3e}, {hi:.3e}] "
                f"| {se / p:.3f} | {ref['p']:.3e} | {z:+.2f} | {covered} "
                f"| {g['ess']:.0f} | {k} |"
            )
    figure_4(args.out, ref_by_gamma)
    ref = ref_by_gamma[float(GAMMA)]
    n = reference["n"]
    print(f"\nBy mechanism at gamma = {GAMMA} s: p (share of the hits).\n")
    labels = [m["label"] for m in next(iter(mechanisms.values()))]
    print("| mechanism | reference | " + " | ".join(mechanisms) + " |")
    print("|---|---:|" + "---:|" * len(mechanisms))
    codes = ("no_contact", "rear_end", "hit_from_behind", "side")
    for code, label in enumerate(labels):
        hits = ref["hits_by_contact"][codes[code]]
        cells = [f"{hits / n:.2e} ({hits / ref['n_hits']:.0%})"]
        for rows in mechanisms.values():
            row = next((m for m in rows if m["code"] == code), None)
            cells.append("-" if row is None else f"{row['p']:.2e} ({row['share']:.0%})")
        print(f"| {label} | " + " | ".join(cells) + " |")


def figure_4(out: Path, ref_by_gamma: dict[float, dict]) -> Path:
    """The paper's Fig. 4 for each importance sampler: rare events and variance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (hits_ax, var_ax) = plt.subplots(1, 2, figsize=(9, 3.4))
    for name in ("ce", "splitting_is"):
        path = out / f"{name}.json"
        if not path.is_file():
            continue
        (result,) = json.loads(path.read_text())["runs"]
        settings = json.loads((out / "runs" / name / "summary.json").read_text())
        n_final = settings["settings"].get("n_final", result["n_rollouts"])
        rows = [g for g in result["by_gamma"] if g["gamma"] in ref_by_gamma]
        gammas = [g["gamma"] for g in rows]
        p_ref = np.array([ref_by_gamma[g]["p"] for g in gammas])
        hits = np.array([g["n_hits"] for g in rows])
        variance = np.array([g["stderr"] ** 2 for g in rows])
        n = result["n_rollouts"]
        hits_ax.plot(gammas, hits / (p_ref * n_final), "o-", label=name)
        var_ax.plot(gammas, p_ref * (1 - p_ref) / n / variance, "o-", label=name)
    hits_ax.set(
        xlabel="threshold gamma [s]",
        ylabel="rare events: hits / naive's expected",
        title="(a) rare events, vs naive at the final stage's size",
    )
    var_ax.set(
        xlabel="threshold gamma [s]",
        ylabel="naive variance / method's",
        title="(b) variance, vs naive at the run's budget",
    )
    for ax in (hits_ax, var_ax):
        ax.set_yscale("log")
        ax.title.set_fontsize(9)
        ax.legend(fontsize=8)
    fig.tight_layout()
    target = out / "fig4.png"
    fig.savefig(target, dpi=110)
    plt.close(fig)
    return target


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    runs = sub.add_parser("run", help="Run the methods.")
    runs.add_argument("--device", default="cuda")
    runs.add_argument("--seed", type=int, default=1)
    runs.add_argument("--batch-size", type=int, default=8192)
    runs.add_argument("--methods", default=",".join(METHODS))
    runs.add_argument("--out", type=Path, required=True)
    tables = sub.add_parser("table", help="Print the runs against a reference.")
    tables.add_argument("--out", type=Path, required=True)
    tables.add_argument("--reference", type=Path, required=True)
    args = parser.parse_args(argv)
    run(args) if args.command == "run" else table(args)


if __name__ == "__main__":
    main()
