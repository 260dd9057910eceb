"""The estimators on ``highway_idm``'s P0 with an analytic ``f``: any bias there?

``f`` is the time to collision of the ego and the slow vehicle from their initial
states alone (gap over closing speed; 100 s when not closing), so its tail is a
joint tail of four of the 24 Beta coordinates, as the simulator's crashes are.
A 20-million-sample naive estimate is exact enough to judge CE, mixture CE and
subset simulation at the coverage benchmark's budgets (10 seeds each).

Usage (about 10 minutes on one core)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/analytic_ttc_proxy.py
"""

from __future__ import annotations

import warnings

import numpy as np

from avrisk.assembly import base_distribution
from avrisk.rare import estimate
from avrisk.scenario import load_spec

GAMMAS = (0.5, 0.8, 1.0)
BUDGETS = {
    "mixture": dict(rho=0.1, n_per_iter=2000, n_iter=5, n_final=10000),
    "ce": dict(rho=0.1, n_per_iter=2000, n_iter=5, n_final=10000),
    "splitting": dict(n_particles=4000),
}


def ttc(x: np.ndarray, seeds: np.ndarray | None = None) -> np.ndarray:
    """Initial TTC [s], shape (n,): the ego (columns 0, 3), the slow car (4, 7)."""
    gap = (x[:, 4] + 48.0) - x[:, 0] - 4.8
    closing = x[:, 3] - x[:, 7]
    return np.maximum(
        np.where(closing > 0, gap / np.maximum(closing, 1e-9), 100.0), 0.0
    )


def main() -> None:
    base = base_distribution(load_spec("highway_idm"))
    rng = np.random.default_rng(1)
    n, hits = 0, dict.fromkeys(GAMMAS, 0)
    for _ in range(40):
        values = ttc(base.sample(500_000, rng))
        n += values.size
        for g in GAMMAS:
            hits[g] += int(np.count_nonzero(values <= g))
    print(f"naive, {n:,} samples:")
    for g in GAMMAS:
        print(f"  p({g:g}) = {hits[g] / n:.4g} +- {np.sqrt(hits[g]) / n:.2g}")
    for method, settings in BUDGETS.items():
        estimates = []
        for seed in range(10):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = estimate(
                    method,
                    ttc,
                    base,
                    GAMMAS[0],
                    seed=seed,
                    gamma_test=GAMMAS[1:],
                    **settings,
                )
            estimates.append([est.by_gamma[g].p for g in GAMMAS])
        p = np.array(estimates)
        se = p.std(axis=0, ddof=1) / np.sqrt(len(p))
        print(f"{method}, 10 seeds (mean +- its standard error):")
        for g, mean, err in zip(GAMMAS, p.mean(axis=0), se, strict=True):
            print(f"  p({g:g}) = {mean:.4g} +- {err:.2g}")


if __name__ == "__main__":
    main()
