"""Estimator efficiency at a fixed budget of calls of f, on problems with exact answers.

For each problem and method: mean calls of f, relative bias and relative RMSE
over ``--seeds`` repetitions, 95% CI coverage, and the speed-up over naive Monte
Carlo = (naive relative variance at the same budget, (1-p)/(n p)) / (relative
MSE of the method): how many times more calls naive MC needs for the same
accuracy. OpenTURNS's cross-entropy importance sampling runs side by side when
installed (``pip install avrisk[bench]``); its budget is set by its own stopping
rule, so its mean number of calls is reported with it. So is subset simulation's,
which makes one level per factor of about ``p0 = 0.1`` in ``p``.

    python benchmarks/estimators.py [--budget 100000] [--seeds 20] \
        [--problems four_branch,gaussian_linear_d1000] [--methods splitting,CE]
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from avrisk.rare import (
    Estimate,
    UnreliableEstimateWarning,
    cross_entropy,
    mixture_ce,
    naive_mc,
    splitting_is,
    subset_simulation,
)
from avrisk.testing import (
    AnalyticProblem,
    beta_sum_problem,
    four_branch_problem,
    gaussian_linear_problem,
    mixed_problem,
)

try:
    import openturns as ot
except ImportError:  # optional comparator
    ot = None

Run = Callable[[AnalyticProblem, int], tuple[float, float, float, int]]


def _estimator_run(method: Callable[..., Estimate], **settings: Any) -> Run:
    """A run of ``method(f, base, gamma, seed=seed, **settings)`` per problem and seed.

    Degenerate runs (``UnreliableEstimateWarning``) are part of what the RMSE
    measures, so their warnings are silenced.
    """

    def run(problem: AnalyticProblem, seed: int) -> tuple[float, float, float, int]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnreliableEstimateWarning)
            est = method(problem.f, problem.base, problem.gamma, seed=seed, **settings)
        return _unpack(est)

    return run


def avrisk_ce(budget: int, select: str) -> Run:
    n_iter, n_per_iter = 10, budget // 25
    n_final = budget - n_iter * n_per_iter
    run = _estimator_run(
        cross_entropy,
        rho=0.1,
        alpha=0.8,
        n_per_iter=n_per_iter,
        n_iter=n_iter,
        n_final=n_final,
        select=select,
    )
    run.label = f"avrisk CE, select={select} ({n_iter}x{n_per_iter} + {n_final})"
    return run


def avrisk_mixture(budget: int) -> Run:
    """Mixture CE with its defaults (4 components, defensive 0.1) at CE's rho.

    It searches for 8 iterations, not CE's 10: at rho = 0.1 the levels reach
    gamma by the 6th for these probabilities, and the rest goes to the final
    stage, which pays for the defensive share.
    """
    n_iter, n_per_iter = 8, budget // 25
    n_final = budget - n_iter * n_per_iter
    run = _estimator_run(
        mixture_ce, rho=0.1, n_per_iter=n_per_iter, n_iter=n_iter, n_final=n_final
    )
    run.label = f"avrisk mixture CE, 4 components ({n_iter}x{n_per_iter} + {n_final})"
    return run


def avrisk_naive(budget: int) -> Run:
    def run(problem: AnalyticProblem, seed: int) -> tuple[float, float, float, int]:
        return _unpack(
            naive_mc(problem.f, problem.base, problem.gamma, budget, seed=seed)
        )

    run.label = "avrisk naive MC"
    run.is_reference = True
    return run


def avrisk_splitting(budget: int) -> Run:
    """Subset simulation with ``budget // 6`` particles per level.

    That spends about the budget at p ~ 1e-6 (6 levels of 0.9 N new calls
    after the first N); likelier events stop sooner, with fewer calls.
    """
    n_particles = budget // 6
    run = _estimator_run(subset_simulation, n_particles=n_particles)
    run.label = f"avrisk subset simulation (N={n_particles:,}, p0=0.1)"
    return run


def avrisk_splitting_is(budget: int) -> Run:
    """Subset simulation with ``budget // 14`` particles, then IS of ``budget // 2``.

    At p ~ 1e-6 the levels (about 5.5 N), the moves at gamma (N) and the final
    stage spend about the budget; likelier events fewer.
    """
    n_particles, n_final = budget // 14, budget // 2
    run = _estimator_run(splitting_is, n_particles=n_particles, n_final=n_final)
    run.label = f"avrisk splitting + IS (N={n_particles:,}, then {n_final:,})"
    return run


def _unpack(est: Estimate) -> tuple[float, float, float, int]:
    return est.p, est.ci[0], est.ci[1], est.n_evals


def openturns_ce(budget: int) -> Run:
    """OpenTURNS CE-IS: standard space for Gaussian blocks, physical space for Betas."""
    block = budget // 6  # ~5 levels + final stage at rho = 0.1 for p ~ 1e-5..1e-6

    def run(problem: AnalyticProblem, seed: int) -> tuple[float, float, float, int]:
        ot.RandomGenerator.SetSeed(seed)
        calls = [0]
        dim = problem.base.dim

        def g(x: np.ndarray) -> np.ndarray:
            x = np.asarray(x)
            calls[0] += len(x)
            return problem.f(x)[:, None]

        dist, aux, active, init, bounds = _ot_distributions(problem)
        vector = ot.CompositeRandomVector(
            ot.PythonFunction(dim, 1, func_sample=g), ot.RandomVector(dist)
        )
        event = ot.ThresholdEvent(vector, ot.LessOrEqual(), problem.gamma)
        if aux is None:
            algo = ot.StandardSpaceCrossEntropyImportanceSampling(event, 0.1)
        else:
            algo = ot.PhysicalSpaceCrossEntropyImportanceSampling(
                event, aux, active, init, bounds, 0.1
            )
        algo.setMaximumOuterSampling(block)
        algo.run()
        res = algo.getResult()
        p = res.getProbabilityEstimate()
        half = 1.959964 * res.getStandardDeviation()
        return p, max(0.0, p - half), p + half, calls[0]

    run.label = f"OpenTURNS CE-IS (rho=0.1, {block} per level)"
    return run


def _ot_distributions(problem: AnalyticProblem):
    """OpenTURNS twins of the base and, when it has Beta blocks, the auxiliary family.

    Pure normal problems go to the standard-space algorithm (no auxiliary
    family). Otherwise the auxiliary family is the base with active parameters
    the Beta shapes (box as in avrisk) and the normal means (unconstrained,
    like avrisk's ``max_shift=None``); parameters are indexed over the joint
    distribution, Beta marginals having 4 and normal ones 2.
    """
    marginals, active, init, low, high = [], [], [], [], []
    offset, has_beta = 0, False
    for block in getattr(problem.base, "blocks", (problem.base,)):
        d = block.to_dict()
        if d["family"] == "ScaledBeta":
            has_beta = True
            marginals.append(ot.Beta(d["a"], d["b"], d["lo"], d["lo"] + d["scale"]))
            active += [offset, offset + 1]
            init += [d["a"], d["b"]]
            low += [d["bounds"][0]] * 2
            high += [d["bounds"][1]] * 2
            offset += 4
            continue
        for mean in d["mean"]:  # the problems use N(mean, I)
            marginals.append(ot.Normal(mean, 1.0))
            active.append(offset)
            init.append(mean)
            low.append(mean - 10.0)
            high.append(mean + 10.0)
            offset += 2
    dist = ot.JointDistribution(marginals)
    if not has_beta:
        return dist, None, None, None, None
    return dist, ot.JointDistribution(marginals), active, init, ot.Interval(low, high)


def evaluate(run: Run, problem: AnalyticProblem, seeds: int) -> dict[str, float]:
    rows, start = [], time.perf_counter()
    for seed in range(seeds):
        rows.append(run(problem, seed))
    wall = (time.perf_counter() - start) / seeds
    p, lo, hi, calls = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    rel = p / problem.p_exact - 1
    n = calls.mean()
    rmse = float(np.sqrt(np.mean(rel**2)))
    naive_rel_var = (1 - problem.p_exact) / (n * problem.p_exact)
    return {
        "calls": n,
        "bias": float(rel.mean()),
        "rmse": rmse,
        "coverage": float(np.mean((lo <= problem.p_exact) & (problem.p_exact <= hi))),
        "speedup": naive_rel_var / rmse**2 if rmse > 0 else float("inf"),
        "seconds": wall,
    }


def _short_name(label: str) -> str:
    """``"avrisk CE, select=..."`` -> ``"CE,"`` stripped: the word after 'avrisk'."""
    words = label.split()
    return (words[1] if words[0] == "avrisk" else words[0]).rstrip(",")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=100_000)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument(
        "--problems", help="Comma-separated problem names (default: all)."
    )
    parser.add_argument(
        "--methods",
        help="Comma-separated labels' first words after 'avrisk' "
        "(naive, CE, subset, mixture, splitting) or 'OpenTURNS' (default: all).",
    )
    args = parser.parse_args()
    problems = [
        gaussian_linear_problem(2, p=1e-6),
        gaussian_linear_problem(100, p=1e-6),
        gaussian_linear_problem(1000, p=1e-6),
        beta_sum_problem(6, p=1e-5, bounds=(1.5, 7.0)),
        mixed_problem(1e-2, 1e-3),
        four_branch_problem(),
    ]
    methods = [
        avrisk_naive(args.budget),
        avrisk_ce(args.budget, "quantile"),
        avrisk_ce(args.budget, "variance"),
        avrisk_splitting(args.budget),
        avrisk_mixture(args.budget),
        avrisk_splitting_is(args.budget),
    ]
    if ot is not None:
        methods.append(openturns_ce(args.budget))
    else:
        print("(OpenTURNS not installed: `pip install avrisk[bench]` to compare)")
    if args.problems:
        wanted = set(args.problems.split(","))
        problems = [p for p in problems if p.name in wanted]
    if args.methods:
        wanted = set(args.methods.split(","))
        methods = [m for m in methods if _short_name(m.label) in wanted]
    print(f"budget {args.budget:,} calls of f, {args.seeds} seeds\n")
    print(
        "| problem | exact p | method | mean calls | rel. bias | rel. RMSE | "
        "95% CI coverage | speed-up vs naive | s/run |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for problem in problems:
        for run in methods:
            r = evaluate(run, problem, args.seeds)
            # naive MC is the reference: its speed-up is 1 by definition (an empirical
            # RMSE over a few seeds of a 1e-6 event is mostly luck)
            speedup = (
                "1 (ref.)"
                if getattr(run, "is_reference", False)
                else f"{r['speedup']:,.0f}"
            )
            print(
                f"| {problem.name} | {problem.p_exact:.3g} | {run.label} "
                f"| {r['calls']:,.0f} | "
                f"{r['bias']:+.4f} | {r['rmse']:.4f} | {r['coverage']:.0%} | "
                f"{speedup} | {r['seconds']:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
