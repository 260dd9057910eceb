"""p under other initial-condition marginals, all else fixed (issue 44, item 5).

``highway_default``'s starts are the paper's marginals (O'Kelly et al. 2018):
every slot's speed ``10 + 10 Beta(2, 2)`` m/s but the slow vehicle's (``0 +
9 Beta(2, 2)``). Set beside the shipped I-80 car-following data
(``benchmarks/initial_conditions.py``, BENCHMARKS.md "The starts P0 draws
against the I-80 data"), its traffic is faster than the data's (median 15
against 6.1 m/s). The slow vehicle's speed already lies within the data's.
This runs one estimation per variant of the traffic slots' speed marginal
(the ego, its neighbours, the follower, the long vehicle; the slow vehicle
keeps its own), the drivers, the ego and every other marginal held fixed,
and prints each ``p`` with its interval, then the spread over the variants::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/marginal_p_spread.py \\
        [--variants paper,flowing,ego_speeds] [--seed 0] [--out runs/marginal_p]

The variants, fixed before any was run, from the data's percentiles
(``benchmarks/results/initial_conditions.json``, p5 / p50 / p95 of the
follower's speed in each band; a Beta(2, 2) on ``[lo, lo + scale]`` has its
p5 / p50 / p95 at ``lo + (0.135, 0.5, 0.865) scale``):

* ``paper``: ``10 + 10 Beta(2, 2)`` (11.35 / 15 / 18.65), the shipped scenario;
* ``flowing``: ``4 + 8.5 Beta(2, 2)`` (5.15 / 8.25 / 11.35), the data's rows
  whose leader drives at 5 m/s or more (4.75 / 7.54 / 11.7);
* ``ego_speeds``: ``9.5 + 6 Beta(2, 2)`` (10.31 / 12.5 / 14.69), the data's rows
  whose follower drives at P0's ego speeds, 10-20 m/s (10.1 / 11.1 / 14.5).

Each run goes to ``OUT/<variant>`` (resumed or read back when run again, as
``avrisk run`` does) with ``splitting_is`` at ``avrisk run``'s defaults, and
its row to ``OUT/marginal_p.jsonl``. The spread is shown as its own range
beside each run's interval, not folded into it: the estimators' coverage is
measured under the shipped marginals.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from avrisk.api import estimate
from avrisk.scenario.loading import load_spec

SCENARIO = "highway_default"
#: name -> the traffic slots' speed marginal ``lo + scale Beta(2, 2)`` [m/s].
VARIANTS: dict[str, tuple[float, float]] = {
    "paper": (10.0, 10.0),
    "flowing": (4.0, 8.5),
    "ego_speeds": (9.5, 6.0),
}


def variant_spec(name: str) -> dict[str, Any]:
    """``highway_default`` with the traffic slots' speed marginal of ``name``."""
    spec = load_spec(SCENARIO).model_dump(mode="json")
    lo, scale = VARIANTS[name]
    spec["initial_conditions"]["speed"] |= {"lo": lo, "scale": scale}
    if name != "paper":
        spec["name"] = f"{SCENARIO}_speeds_{name}"
    return spec


def run_variant(name: str, seed: int, out: Path) -> dict[str, Any]:
    """One estimation of the variant; its row."""
    start = time.perf_counter()
    result = estimate(variant_spec(name), out=out / name, seed=seed, failures=0)
    row = result.estimate
    main = next(g for g in row["by_gamma"] if g["gamma"] == row["gamma"])
    trust = result.answer().trust
    return {
        "variant": name,
        "speed": dict(zip(("lo", "scale"), VARIANTS[name], strict=True)),
        "seed": seed,
        "gamma": row["gamma"],
        "p": main["p"],
        "ci": main["ci"],
        "n_hits": main["n_hits"],
        "ess": main.get("ess"),
        "pareto_k": main.get("pareto_k"),
        "p_by_gamma": result.by_gamma,
        "n_evals": row["n_evals"],
        "trust": trust.word,
        "reasons": list(trust.reasons),
        "seconds": time.perf_counter() - start,
    }


def main(argv: list[str] | None = None) -> None:
    """Command line: the variants' runs and the spread."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("runs/marginal_p"))
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.variants.split(","):
        row = run_variant(name, args.seed, args.out)
        rows.append(row)
        with (args.out / "marginal_p.jsonl").open("a") as sink:
            sink.write(json.dumps(row) + "\n")
        lo, hi = row["ci"]
        print(
            f"{name:>11}: p({row['gamma']:g} s) = {row['p']:.3g} "
            f"[{lo:.3g}, {hi:.3g}], {row['n_evals']:,} rollouts, "
            f"{row['seconds']:.0f} s; {row['trust']}",
            flush=True,
        )
    found = [r["p"] for r in rows if r["p"] > 0]
    if len(found) > 1:
        print(f"spread over the variants: {min(found):.3g} to {max(found):.3g}")


if __name__ == "__main__":
    main()
