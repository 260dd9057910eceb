"""Measure ``p_gamma = P0(min TTC <= gamma)`` of a scenario (default: the bundled one).

Naive Monte Carlo (``avrisk.rare.naive_mc``) for the thresholds it can resolve;
for the rarer ones, importance sampling from a defensive mixture of P0 and a
hand-made proposal that shifts the four coordinates that matter (``--shifted``),
and/or the cross-entropy method (``avrisk.rare.cross_entropy``, ``--ce``).
Prints a markdown table and draws ``p_gamma`` against ``gamma``: the naive
empirical curve with its 95% Clopper-Pearson band, and the importance-sampling
estimates with their 95% intervals. A tool for calibrating a scenario's
rarity; the bundled ``highway_idm`` is calibrated in BENCHMARKS.md by a
300,000-rollout naive run and ``benchmarks/ce_vs_naive.py``.

Usage (one CPU thread each, a few minutes each)::

    .venv/bin/python benchmarks/default_scenario_rates.py --naive 20000 \
        --seed 41 --threads 1 --figure naive.png
    .venv/bin/python benchmarks/default_scenario_rates.py --naive 0 \
        --shifted 10000 --seed 40 --threads 1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from avrisk.assembly import ScenarioSimulator, base_distribution, param_layout
from avrisk.rare import Product, ScaledBeta, cross_entropy, naive_mc
from avrisk.rare.final_stage import importance_estimates
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import ParamLayout, load_spec

GAMMAS = (0.1, 0.2, 0.3)

#: A hand-made importance proposal (``--shifted``, used as half of a defensive
#: mixture with P0): the ego starts far forward
#: and fast, the slow vehicle ahead of it far back and slow -- the corner of P0
#: where the ego cannot brake in time. Shapes (a, b) inside the CE search box.
CORNER_SHIFT = {
    "veh0.s": (7.0, 1.5),
    "veh1.s": (1.5, 7.0),
    "veh0.speed": (7.0, 1.5),
    "veh1.speed": (1.5, 7.0),
}


def shifted_proposal(p0: Product, layout: ParamLayout, shift: dict) -> Product:
    """``p0`` with the named one-dimensional Beta blocks given new shapes (a, b)."""
    blocks = list(p0.blocks)
    for column, (a, b) in shift.items():
        old = blocks[layout.index(column)]
        blocks[layout.index(column)] = ScaledBeta(a, b, old.lo, old.scale, old.bounds)
    return Product(blocks)


class CountingObjective:
    """``f(X)`` = minimum TTC [s] of fresh rollouts; keeps every value it returns.

    Each call gets seeds from a running counter (the IDM+MOBIL agents are
    deterministic, so seeds do not change ``f``; they would with noisy agents).
    """

    def __init__(self, sim: ScenarioSimulator, seed: int, label: str) -> None:
        self.sim, self.seed, self.label = sim, seed, label
        self.n = 0
        self.values: list[np.ndarray] = []
        self.start = time.perf_counter()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        seeds = sample_seeds(self.seed, 0, np.arange(self.n, self.n + len(x)))
        f = self.sim.min_ttc(x, seeds)
        self.n += len(x)
        self.values.append(f)
        rate = self.n / (time.perf_counter() - self.start)
        print(
            f"\r{self.label}: {self.n} rollouts ({rate:.0f}/s)", end="", file=sys.stderr
        )
        return f


def _cp_band(k: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    lo = np.where(k > 0, stats.beta.ppf(0.025, np.maximum(k, 1), n - k + 1), 0.0)
    hi = np.where(k < n, stats.beta.ppf(0.975, k + 1, np.maximum(n - k, 1)), 1.0)
    return lo, hi


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway_idm")
    parser.add_argument("--naive", type=int, default=20_000, help="Naive MC rollouts.")
    parser.add_argument("--ce", action="store_true", help="Also run cross-entropy.")
    parser.add_argument(
        "--shifted",
        type=int,
        default=0,
        help="Rollouts of defensive-mixture IS: half P0, half CORNER_SHIFT.",
    )
    parser.add_argument("--ce-gamma", type=float, default=0.1)
    parser.add_argument("--ce-iter", type=int, default=10)
    parser.add_argument("--ce-per-iter", type=int, default=2000)
    parser.add_argument("--ce-final", type=int, default=20_000)
    parser.add_argument("--ce-rho", type=float, default=0.05)
    parser.add_argument("--batch-size", type=int, default=2048)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=None, help="Torch CPU threads.")
    parser.add_argument("--figure", type=Path)
    parser.add_argument(
        "--replot", type=Path, help="Draw from a saved mixture_samples.npz only."
    )
    parser.add_argument(
        "--naive-json", type=Path, help="Add the naive points of an earlier --json."
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)

    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    spec = load_spec(args.scenario)
    sim = ScenarioSimulator(spec)
    p0 = base_distribution(spec)
    rows, record = [], {"scenario": spec.name, "command": " ".join(sys.argv)}

    naive_f = None
    if args.naive:
        obj = CountingObjective(sim, args.seed, "naive MC")
        est = naive_mc(
            obj,
            p0,
            GAMMAS[0],
            args.naive,
            seed=args.seed,
            gamma_test=GAMMAS[1:],
            batch_size=args.batch_size,
        )
        print(file=sys.stderr)
        naive_f = np.concatenate(obj.values)
        for g in GAMMAS:
            e = est.by_gamma[g]
            rows.append(("naive MC", args.naive, g, e.p, e.stderr, e.ci, e.n_hits))
        record["naive"] = est.to_dict()
        record["naive_wall_s"] = est.wall_time_s
    if args.shifted:
        # Defensive mixture (Hesterberg 1995): half the rollouts from P0, half
        # from the corner proposal q, all weighted by p0 / (p0/2 + q/2) <= 2, so
        # mechanisms outside the corner are still estimated without blow-ups.
        layout = param_layout(spec)
        q = shifted_proposal(p0, layout, CORNER_SHIFT)
        half = args.shifted // 2
        x = np.concatenate(
            [
                p0.sample(half, chunk_rng(args.seed + 2, 0, 0)),
                q.sample(args.shifted - half, chunk_rng(args.seed + 3, 0, 0)),
            ]
        )
        obj = CountingObjective(sim, args.seed + 2, "mixture IS")
        values = np.concatenate(
            [obj(x[i : i + args.batch_size]) for i in range(0, len(x), args.batch_size)]
        )
        print(file=sys.stderr)
        log_p0 = p0.log_prob(x)
        log_mix = np.logaddexp(log_p0, q.log_prob(x)) - np.log(2.0)
        log_w = log_p0 - log_mix
        by_gamma = importance_estimates(values, log_w, GAMMAS)
        for g in GAMMAS:
            e = by_gamma[g]
            rows.append(("mixture IS", args.shifted, g, e.p, e.stderr, e.ci, e.n_hits))
        record["mixture_is"] = {str(g): e.to_dict() for g, e in by_gamma.items()}
        record["corner_proposal"] = {k: list(v) for k, v in CORNER_SHIFT.items()}
        np.savez_compressed(
            "mixture_samples.npz", x=x, f=values, log_w=log_w, columns=layout.columns
        )
    if args.ce:
        obj = CountingObjective(sim, args.seed + 1, "cross-entropy")
        est = cross_entropy(
            obj,
            p0,
            args.ce_gamma,
            rho=args.ce_rho,
            n_per_iter=args.ce_per_iter,
            n_iter=args.ce_iter,
            n_final=args.ce_final,
            seed=args.seed + 1,
            gamma_test=[g for g in GAMMAS if g != args.ce_gamma],
            batch_size=args.batch_size,
        )
        print(file=sys.stderr)
        for g in sorted(est.by_gamma):
            e = est.by_gamma[g]
            rows.append(("cross-entropy", obj.n, g, e.p, e.stderr, e.ci, e.n_hits))
        record["ce"] = est.to_dict()

    print(f"\nscenario {spec.name}; command: {' '.join(sys.argv)}\n")
    print("| method | rollouts | gamma [s] | p_gamma | stderr | 95% CI | hits |")
    print("|---|---:|---:|---:|---:|---|---:|")
    for method, n, g, p, se, ci, hits in rows:
        print(
            f"| {method} | {n:,} | {g:g} | {p:.3g} | {se:.2g} | "
            f"[{ci[0]:.2g}, {ci[1]:.2g}] | {hits} |"
        )
    if args.json:
        args.json.write_text(json.dumps(record, indent=2, default=str))
    if args.figure:
        mixture = None
        if args.replot:
            data = np.load(args.replot)
            mixture = (data["f"], data["log_w"])
        elif args.shifted:
            mixture = (values, log_w)
        naive_points = []
        if args.naive_json:
            for e in json.loads(args.naive_json.read_text())["naive"]["by_gamma"]:
                naive_points.append((e["gamma"], e["p"], e["ci"], e["n_samples"]))
        draw_figure(args.figure, spec.name, naive_f, mixture, naive_points)
        print(f"\nwrote {args.figure}")


def _weighted_curve(
    f: np.ndarray, log_w: np.ndarray, grid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """IS estimate of ``P0(f <= g)`` and its standard error at each ``g``."""
    w = np.exp(log_w)
    hits = f[None, :] <= grid[:, None]
    terms = w[None, :] * hits
    p = terms.mean(axis=1)
    se = terms.std(axis=1, ddof=1) / np.sqrt(len(f))
    return p, se


def draw_figure(out, name, naive_f, mixture, naive_points) -> None:
    """p_gamma against gamma: naive curve / points, IS curve with 95% bands."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.linspace(0.05, 1.0, 96)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.fill_between(
        [0.1, 0.3], 1e-6, 1e-3, color="0.88", zorder=0, label="target: 1e-6..1e-3"
    )
    if mixture is not None:
        f, log_w = mixture
        p, se = _weighted_curve(f, log_w, grid)
        ax.fill_between(
            grid, np.maximum(p - 1.96 * se, 1e-9), p + 1.96 * se, alpha=0.3, color="C2"
        )
        ax.plot(
            grid,
            np.where(p > 0, p, np.nan),
            color="C2",
            label=f"mixture IS, n={len(f):,}",
        )
    if naive_f is not None:
        k = (naive_f[None, :] <= grid[:, None]).sum(axis=1)
        n = len(naive_f)
        lo, hi = _cp_band(k, n)
        ax.fill_between(grid, np.maximum(lo, 1e-9), hi, alpha=0.25, color="C0")
        ax.plot(
            grid, np.where(k > 0, k / n, np.nan), color="C0", label=f"naive MC, n={n:,}"
        )
    for i, (g, p, ci, n) in enumerate(naive_points):
        shown = max(p, 1e-7)
        ax.errorbar(
            [g],
            [shown],
            yerr=[[shown - max(ci[0], 1e-7)], [ci[1] - shown]],
            fmt="o" if p > 0 else "v",
            color="C0",
            capsize=3,
            label=f"naive MC, n={n:,} (95% CP)" if i == 0 else None,
        )
    ax.set_yscale("log")
    ax.set_ylim(1e-7, 1.0)
    ax.set_xlabel("gamma [s]")
    ax.set_ylabel("p_gamma = P0(min TTC <= gamma)")
    ax.set_title(f"{name}: rarity of dangerous events")
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
