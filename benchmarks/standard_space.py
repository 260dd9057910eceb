"""CE in the base's own family against CE in its standard-normal space.

Six ``80 + 40 Beta(2, 2)`` below a threshold with exact p = 1e-8
(``avrisk.testing.beta_sum_problem``), the Beta shapes in the bundled
scenarios' CE box [1, 3.9], where the boxed Beta proposals cannot concentrate
on the corner of the support. Same budget and seeds for both; prints, per
space, the mean relative bias, the relative RMSE, the mean reported relative
standard error and the coverage of the 95% intervals::

    python benchmarks/standard_space.py [--seeds 20] [--p 1e-8]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from avrisk.rare import cross_entropy
from avrisk.testing import beta_sum_problem

SETTINGS = dict(rho=0.1, n_per_iter=2000, n_iter=8, n_final=20_000)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--p", type=float, default=1e-8)
    args = parser.parse_args()
    problem = beta_sum_problem(6, p=args.p, bounds=(1.0, 3.9))
    budget = SETTINGS["n_iter"] * SETTINGS["n_per_iter"] + SETTINGS["n_final"]
    print(
        f"{problem.name}, exact p = {problem.p_exact:.3g}, {budget:,} calls, "
        f"{args.seeds} seeds\n"
    )
    print("| space | rel. bias | rel. RMSE | mean reported rel. se | 95% CI coverage |")
    print("|---|---:|---:|---:|---:|")
    for space in ("natural", "standard"):
        p, se, covered = [], [], 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for seed in range(args.seeds):
                est = cross_entropy(
                    problem.f,
                    problem.base,
                    problem.gamma,
                    seed=seed,
                    space=space,
                    **SETTINGS,
                )
                p.append(est.p)
                se.append(est.stderr)
                covered += est.ci[0] <= problem.p_exact <= est.ci[1]
        rel = np.array(p) / problem.p_exact - 1.0
        print(
            f"| {space} | {rel.mean():+.3f} | {np.sqrt((rel**2).mean()):.3f} | "
            f"{np.mean(np.array(se) / problem.p_exact):.3f} | "
            f"{covered}/{args.seeds} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
