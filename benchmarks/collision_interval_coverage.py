"""Coverage of the realism report's collision intervals when collisions cluster.

``avrisk realism`` drives every held-out window ``R`` times; a model that cannot
stop behind one window's leader crashes in many of that window's replays, so
the replays are not independent. This simulates reports of ``W`` windows x
``R`` replays in which each window is, independently, crash-prone with a
probability ``share`` (then each of its replays crashes with probability
``p_prone``) or ordinary (``p_base``), and counts how often each interval of
:func:`avrisk.realism.metrics.clustered_event_rate` covers the true rate per
vehicle-hour: the exact Poisson one (replays independent) and the one with
windows as clusters. ``tests/realism/test_metrics.py`` runs a smaller sweep.

Usage::

    .venv/bin/python benchmarks/collision_interval_coverage.py [--reports 2000]
"""

from __future__ import annotations

import argparse

import numpy as np

from avrisk.realism.metrics import clustered_event_rate

#: Regimes: (share of crash-prone windows, their crash probability per
#: replay, the other windows' crash probability per replay).
REGIMES = {
    "independent": (0.0, 0.0, 0.002),
    "5% prone, p 0.05": (0.05, 0.05, 0.0),
    "2% prone, p 0.3": (0.02, 0.3, 0.0005),
    "1% prone, p 0.5": (0.01, 0.5, 0.0),
    "0.5% prone, p 0.5": (0.005, 0.5, 0.0),
}


def coverage(
    regime: tuple[float, float, float],
    reports: int,
    rng: np.random.Generator,
    windows: int = 202,
    replicates: int = 24,
    window_s: float = 15.0,
) -> dict[str, float]:
    """Share of ``reports`` simulated reports whose intervals cover the rate."""
    share, p_prone, p_base = regime
    hours = windows * replicates * window_s / 3600
    truth = (share * p_prone + (1 - share) * p_base) * replicates * windows / hours
    hits = {"ci95": 0, "ci95_windows": 0}
    for _ in range(reports):
        prone = rng.random(windows) < share
        counts = rng.binomial(replicates, np.where(prone, p_prone, p_base))
        rate = clustered_event_rate(counts, hours)
        for key in hits:
            hits[key] += rate[key][0] <= truth <= rate[key][1]
    return {"rate": truth} | {key: n / reports for key, n in hits.items()}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reports", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print(f"{args.reports} reports of 202 windows x 24 replays of 15 s per regime")
    print("| regime | true rate [1/veh-h] | Poisson (replays) | windows as clusters |")
    print("|---|---:|---:|---:|")
    for name, regime in REGIMES.items():
        c = coverage(regime, args.reports, rng)
        cells = f"{c['rate']:.2f} | {c['ci95']:.3f} | {c['ci95_windows']:.3f}"
        print(f"| {name} | {cells} |")


if __name__ == "__main__":
    main()
