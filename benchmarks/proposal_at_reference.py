"""What a naive reference's hits say of a run's importance-sampling proposal.

A naive reference (``device_agreement.py simulate``) records every row near
the event; its hits are draws of ``P0(. | f <= gamma)``, the law an
importance sampler's proposal ``q`` should cover. Weighed under ``q``, each
hit's ``w = p0 / q`` says how the run's importance sample fares there, with
no knowledge of what the run drew: ``E_q[(w 1_F)^2] = p E[w | F]``, so

* the relative variance per draw is ``mean(w over the hits) / p - 1`` (the
  run's relative standard error is its square root over ``sqrt(n_final)``);
* the share of ``p`` where ``w > t`` is the share of hits there, and the draws
  expected there in ``n_final`` are ``n_final p mean(1{w > t} / w)``: a part
  of ``p`` with far fewer than one expected draw is missed by a typical run
  and found, with a large weight, by a rare one -- an estimate whose typical
  value lies below ``p`` and whose interval does not know it.

It runs ``avrisk run``'s estimator (the default method at its defaults, with
``--set`` overrides) once per seed and prints one JSON line per seed::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/proposal_at_reference.py \\
        highway_rare --reference benchmarks/results/references/highway_rare_gpu \\
        --gamma 0.14 --p 2.686e-7 --seeds 4 [--set refresh_rounds=0]

The reference's folder holds one ``*.chunks.jsonl`` per seed of its draws; the
hits are drawn again from their chunks (``device_agreement.near_draws``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from avrisk.assembly import SimulationObjective, base_distribution
from avrisk.rare import estimate as estimate_p
from avrisk.rare.estimator import DEFAULT_METHOD
from avrisk.scenario import load_spec

sys.path.insert(0, str(Path(__file__).parent))
from coverage import _assignment, _seeds  # noqa: E402
from device_agreement import near_draws, read_chunks  # noqa: E402

#: Weights beyond which the share of ``p`` and the expected draws are shown.
WEIGHTS = (1e-5, 1e-4, 1e-3)


def reference_hits(spec, folder: Path, gamma: float) -> np.ndarray:
    """X (R, D) of the rows recorded in ``folder``'s chunks with ``f <= gamma``."""
    parts = []
    for source in sorted(folder.glob("*.chunks.jsonl")):
        _, x, _ = near_draws(spec, read_chunks(source), gamma, 10**9)
        parts.append(x)
    return np.concatenate(parts)


def proposal_at(
    log_p0: np.ndarray, log_q: np.ndarray, p: float, n_final: int
) -> dict[str, float]:
    """The relative variance per draw, and per weight ``t`` of ``WEIGHTS`` the
    share of ``p`` where ``w > t`` and the draws expected there."""
    w = np.exp(log_p0 - log_q)
    out = {"relative_variance_per_draw": float(w.mean() / p - 1.0)}
    for t in WEIGHTS:
        beyond = w > t
        out[f"share_w_above_{t:g}"] = float(beyond.mean())
        out[f"draws_w_above_{t:g}"] = float(n_final * p * np.mean(beyond / w))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario")
    parser.add_argument("--reference", type=Path, required=True)
    parser.add_argument("--gamma", type=float, required=True)
    parser.add_argument("--p", type=float, required=True, help="the reference's p")
    parser.add_argument("--seeds", default="0")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec)
    base = base_distribution(spec)
    hits = reference_hits(spec, args.reference, args.gamma)
    settings = dict(_assignment(text) for text in args.set)
    for seed in _seeds(args.seeds):
        start = time.perf_counter()
        est = estimate_p(
            DEFAULT_METHOD, objective, base, args.gamma, seed=seed, **settings
        )
        line = {
            "scenario": args.scenario,
            "seed": seed,
            "settings": settings,
            "reference_hits": len(hits),
            "p_over_reference": est.p / args.p,
            "ci_over_reference": [c / args.p for c in est.main.ci],
            "ess": est.main.ess,
            "n_evals": est.n_evals,
            "refreshed": est.details.get("refreshed"),
            **proposal_at(
                base.log_prob(hits),
                est.proposal.log_prob(hits),
                args.p,
                est.main.n_samples,
            ),
            "seconds": time.perf_counter() - start,
        }
        print(json.dumps(line), flush=True)


if __name__ == "__main__":
    main()
