"""Cross-entropy vs naive Monte Carlo at an equal budget (the paper's Table 1).

For each of ``--seeds`` seeds, runs the cross-entropy method (``--n-iter``
iterations of ``--n-per-iter`` rollouts, then ``--n-final``) and naive Monte
Carlo with CE's total number of rollouts, on the bundled ``highway_idm``
scenario unless told otherwise. Against a large naive reference run (a finished
``avrisk run --method naive`` directory, ``--reference``), it prints per
threshold, as markdown:

* the reference estimate and its 95% interval;
* the mean and spread over seeds of the CE and naive estimates;
* the rare-event ratio: CE final-stage hits over the naive hits expected with
  CE's whole budget (``n p_ref``);
* the variance ratio, three ways: the naive variance ``p_ref (1 - p_ref) / n``
  over CE's own squared standard error (median over seeds); the same naive
  variance over the CE estimates' variance across seeds (the honest figure:
  it does not trust CE's standard error); and the naive estimates' variance
  over the CE estimates' across seeds (noisy with few seeds: a naive run
  often has 0-5 hits).

Usage (the figures in BENCHMARKS.md; one CPU thread, about 10 minutes)::

    OMP_NUM_THREADS=1 .venv/bin/avrisk run --method naive --n-final 300000 \\
        --gamma 0.1 --gamma-test 0.14,0.2,0.3,0.5,1.0 --seed 100 \\
        --out runs/bench/reference --failures 0
    .venv/bin/python benchmarks/ce_vs_naive.py --reference runs/bench/reference \\
        --seeds 10 --json benchmarks/results/ce_vs_naive.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from avrisk.assembly import SimulationObjective, base_distribution
from avrisk.pipeline import RunDirectory
from avrisk.rare import cross_entropy, naive_mc
from avrisk.scenario import load_spec


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway_idm")
    parser.add_argument("--reference", type=Path, required=True)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument(
        "--first-seed", type=int, default=0, help="Seeds run: first-seed + 0..seeds-1."
    )
    parser.add_argument("--gamma", type=float, default=0.1)
    parser.add_argument("--gamma-test", default="0.2,0.3,0.5,1.0")
    parser.add_argument("--rho", type=float, default=0.1)
    parser.add_argument("--alpha", type=float, default=0.8, help="CE smoothing.")
    parser.add_argument("--n-per-iter", type=int, default=2000)
    parser.add_argument("--n-iter", type=int, default=5)
    parser.add_argument("--n-final", type=int, default=10_000)
    parser.add_argument(
        "--defensive",
        type=float,
        default=0.0,
        help="Share of CE's final stage drawn from P0 (defensive mixture).",
    )
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec)
    base = base_distribution(spec)
    gamma_test = tuple(float(g) for g in args.gamma_test.split(","))
    gammas = (args.gamma, *gamma_test)
    if not (args.reference / "config.json").exists():
        sys.exit(f"{args.reference} is not a run directory")

    records = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # zero-hit naive runs are expected
            ce = cross_entropy(
                objective,
                base,
                args.gamma,
                rho=args.rho,
                alpha=args.alpha,
                n_per_iter=args.n_per_iter,
                n_iter=args.n_iter,
                n_final=args.n_final,
                seed=seed,
                gamma_test=gamma_test,
                defensive=args.defensive,
            )
            naive = naive_mc(
                objective, base, args.gamma, ce.n_evals, seed=1000 + seed,
                gamma_test=gamma_test,
            )  # fmt: skip
        records.append({"seed": seed, "ce": ce.to_dict(), "naive": naive.to_dict()})
        print(
            f"seed {seed}: CE p={ce.p:.3g}+-{ce.stderr:.2g} naive p={naive.p:.3g} "
            f"({time.perf_counter() - start:.0f} s)",
            file=sys.stderr,
        )

    # Read only now: the reference run may still be finishing meanwhile.
    while not (args.reference / "summary.json").exists():
        print("waiting for the reference run to finish ...", file=sys.stderr)
        time.sleep(30)
    reference = RunDirectory(args.reference, objective.layout.columns).summary()
    ref = {g["gamma"]: g for g in reference["estimate"]["by_gamma"]}
    missing = [g for g in gammas if g not in ref]
    if missing:
        sys.exit(f"the reference run has no estimate at gamma = {missing}")

    def by_gamma(method: str, g: float, key: str) -> np.ndarray:
        return np.array(
            [
                next(e[key] for e in r[method]["by_gamma"] if e["gamma"] == g)
                for r in records
            ]
        )

    n = records[0]["ce"]["n_evals"]
    print(
        f"\n{args.seeds} seeds; CE {args.n_iter} x {args.n_per_iter:,} + "
        f"{args.n_final:,} = {n:,} rollouts (rho {args.rho}, alpha {args.alpha}, "
        f"defensive {args.defensive:g}); naive MC {n:,} "
        f"rollouts; reference: naive MC, {reference['estimate']['n_evals']:,} "
        "rollouts.\n"
    )
    print(
        "| gamma [s] | reference p [95% CI] | CE p, mean +- sd | naive p, mean +- sd "
        "| CE hits (final) | naive hits | rare-event ratio | variance ratio: "
        "binomial / CE stderr^2 | binomial / CE var over seeds | naive var / CE var "
        "over seeds |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for g in gammas:
        r = ref[g]
        p_ref = r["p"]
        ce_p, naive_p = by_gamma("ce", g, "p"), by_gamma("naive", g, "p")
        ce_hits = by_gamma("ce", g, "n_hits")
        naive_hits = by_gamma("naive", g, "n_hits")
        ce_se = by_gamma("ce", g, "stderr")
        rare_ratio = ce_hits.mean() / (n * p_ref)
        naive_var = p_ref * (1 - p_ref) / n
        var_ratio_se = np.median(naive_var / ce_se**2)
        var_ratio_binom = naive_var / ce_p.var(ddof=1)
        var_ratio_emp = naive_p.var(ddof=1) / ce_p.var(ddof=1)
        rows.append(
            {
                "gamma": g,
                "reference": r,
                "ce_p_mean": ce_p.mean(),
                "ce_p_sd": ce_p.std(ddof=1),
                "naive_p_mean": naive_p.mean(),
                "naive_p_sd": naive_p.std(ddof=1),
                "ce_hits_mean": ce_hits.mean(),
                "naive_hits_mean": naive_hits.mean(),
                "rare_event_ratio": rare_ratio,
                "variance_ratio_stderr": var_ratio_se,
                "variance_ratio_binomial_over_seeds": var_ratio_binom,
                "variance_ratio_empirical": var_ratio_emp,
            }
        )
        print(
            f"| {g:g} | {p_ref:.3g} [{r['ci'][0]:.2g}, {r['ci'][1]:.2g}] "
            f"| {ce_p.mean():.3g} +- {ce_p.std(ddof=1):.2g} "
            f"| {naive_p.mean():.3g} +- {naive_p.std(ddof=1):.2g} "
            f"| {ce_hits.mean():.0f} | {naive_hits.mean():.1f} | {rare_ratio:.0f}x "
            f"| {var_ratio_se:.0f}x | {var_ratio_binom:.0f}x | {var_ratio_emp:.0f}x |"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps(
                {"command": " ".join(sys.argv), "rows": rows, "runs": records},
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
