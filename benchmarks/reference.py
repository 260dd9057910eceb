"""A large naive Monte Carlo reference, in resumable chunks, with provenance.

Simulates the final stage of ``avrisk run SCENARIO --method naive --seed SEED``
chunk by chunk (8,192 rollouts each, the engine's sampling chunks: chunk ``j``
holds exactly that run's rollouts ``8192 j ..``), and appends one JSON line
per chunk to ``OUT.chunks.jsonl``: its hits at every threshold, split by the
contact of the rollout (no contact: a near miss; rear-end, hit from behind, side), its
failed rollouts and its wall time. Nothing but those counts is kept, so
millions of rollouts take a few hundred kilobytes. Stop it at any moment (even
``kill -9``): rerunning the same command skips the chunks recorded and goes
on; raising ``--n`` extends a reference (its last, short chunk is simulated
again in full, and the newer line counts). ``--shard I/K`` makes this process
do chunks ``j = I mod K`` (run K of them side by side on K cores, each into its
own lines file).

``--summarize`` merges every shard's lines into ``OUT.json``: per threshold the
hits, ``p``, its standard error and exact (Clopper-Pearson) 95% interval, the
hits by mechanism, and the provenance stamp (what defines ``p``: the scenario
and weights hashes; how it was computed: code version, device, precision).
Lines recorded for another definition of ``p`` are refused, never mixed in.

Usage (one core; highway_idm runs about 600 rollouts/s, highway_default about
450 eager and about 830 with ``AVRISK_COMPILE=1``, which compiles the step once
per process)::

    OMP_NUM_THREADS=1 nice .venv/bin/python benchmarks/reference.py highway_idm \\
        --n 3000000 --seed 100 --out benchmarks/results/references/highway_idm
    .venv/bin/python benchmarks/reference.py highway_idm --seed 100 \\
        --out benchmarks/results/references/highway_idm --summarize
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy import stats

from avrisk.assembly import SimulationObjective, base_distribution
from avrisk.pipeline.provenance import stamp
from avrisk.rare import RareEventProblem
from avrisk.rare.evaluation import evaluate_task
from avrisk.rare.problem import FINAL_STAGE, SAMPLE_CHUNK
from avrisk.rare.stages import chunk_task
from avrisk.scenario import load_spec

#: Thresholds [s] counted by default (``--gammas`` chooses others).
GAMMAS = (0.1, 0.14, 0.2, 0.3, 0.5, 1.0)
MECHANISMS = ("no_contact", "rear_end", "hit_from_behind", "side")


def lines_path(out: Path, shard: tuple[int, int]) -> Path:
    """The lines file of one shard."""
    i, k = shard
    return out.with_name(f"{out.name}.shard{i}of{k}.chunks.jsonl")


def read_lines(path: Path, definition: dict) -> dict[int, dict]:
    """Recorded chunks of one lines file, by chunk index (checked)."""
    done = {}
    if not path.is_file():
        return done
    for number, text in enumerate(path.read_text().splitlines(), 1):
        if not text.strip():
            continue
        try:
            line = json.loads(text)
        except json.JSONDecodeError:
            if number == len(path.read_text().splitlines()):
                continue  # a line cut short by a kill: done again
            sys.exit(f"{path}:{number}: not JSON")
        if line["defines_p"] != definition:
            sys.exit(
                f"{path}:{number}: recorded for another scenario or other weights "
                "(its defines_p differs); use another --out"
            )
        done[int(line["chunk"])] = line
    return done


def _size(chunk: int, n: int) -> int:
    """Rollouts of chunk ``chunk`` in a reference of ``n`` rollouts."""
    return min(SAMPLE_CHUNK, n - chunk * SAMPLE_CHUNK)


def simulate(args: argparse.Namespace) -> None:
    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec, device=args.device, allow_import=True)
    definition = objective.definition()
    base = base_distribution(spec)
    problem = RareEventProblem(base, objective, gamma=0.0, batch_size=args.batch_size)
    path = lines_path(args.out, args.shard)
    done = read_lines(path, definition)
    n_chunks = -(-args.n // SAMPLE_CHUNK)
    todo = [j for j in range(n_chunks) if j % args.shard[1] == args.shard[0]]
    # A chunk recorded short (the last of a smaller --n) is done again in full.
    todo = [j for j in todo if done.get(j, {}).get("n") != _size(j, args.n)]
    print(f"{len(done)} chunks recorded, {len(todo)} to go", file=sys.stderr)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as sink:
        for j in todo:
            size = _size(j, args.n)
            start = time.perf_counter()
            task = chunk_task(base, args.seed, FINAL_STAGE, j, size)
            result = evaluate_task(problem, task)
            seconds = time.perf_counter() - start
            f = result.values
            failed = result.failed
            contact = result.extras["contact"]
            line = {
                "chunk": j,
                "n": size,
                "seed": args.seed,
                "failed": int(failed.sum()),
                "hits": {
                    f"{g:g}": {
                        m: int(np.sum((f <= g) & ~failed & (contact == code)))
                        for code, m in enumerate(MECHANISMS)
                    }
                    for g in args.gammas
                },
                "seconds": seconds,
                "defines_p": definition,
                "computed_with": objective.computed_with(),
            }
            sink.write(json.dumps(line) + "\n")
            sink.flush()
            os.fsync(sink.fileno())
            print(
                f"chunk {j}: {size / seconds:.0f} rollouts/s, "
                "hits: "
                + ", ".join(
                    f"{sum(counts.values())} at {key} s"
                    for key, counts in line["hits"].items()
                ),
                file=sys.stderr,
            )


def summarize(args: argparse.Namespace) -> None:
    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec, allow_import=True)
    definition = objective.definition()
    lines: dict[int, dict] = {}
    for path in sorted(args.out.parent.glob(f"{args.out.name}.shard*.chunks.jsonl")):
        lines.update(read_lines(path, definition))
    if not lines:
        sys.exit(f"no recorded chunks for {args.out}")
    seeds = {line["seed"] for line in lines.values()}
    if seeds != {args.seed}:
        sys.exit(f"chunks of other seeds {sorted(seeds)} under {args.out}")
    # a reference is the first n rollouts: chunks 0 .. m-1 without a gap
    m = 0
    while m in lines:
        m += 1
    used = [lines[j] for j in range(m)]
    n = sum(line["n"] for line in used)
    seconds = sum(line["seconds"] for line in used)
    # the thresholds every line counted (lines of other --gammas may be mixed)
    keys = set.intersection(*(set(line["hits"]) for line in used))
    by_gamma = []
    for g in sorted(float(key) for key in keys):
        key = f"{g:g}"
        mech = {k: sum(line["hits"][key][k] for line in used) for k in MECHANISMS}
        k = sum(mech.values())
        lo = stats.beta.ppf(0.025, k, n - k + 1) if k else 0.0
        hi = stats.beta.ppf(0.975, k + 1, n - k)
        by_gamma.append(
            {
                "gamma": g,
                "n_hits": k,
                "p": k / n,
                "stderr": float(np.sqrt(k / n * (1 - k / n) / n)),
                "ci": [float(lo), float(hi)],
                "hits_by_contact": mech,
            }
        )
    computed = {json.dumps(line["computed_with"], sort_keys=True) for line in used}
    summary = {
        "schema": "avrisk.reference/1",
        "scenario": spec.name,
        "command": f"avrisk run {spec.name} --method naive --seed {args.seed} "
        f"--n-final {n} (the same rollouts)",
        "seed": args.seed,
        "n": n,
        "n_failed": sum(line["failed"] for line in used),
        "chunks": m,
        "chunks_recorded_beyond": len(lines) - m,
        "by_gamma": by_gamma,
        "cpu_seconds": seconds,
        "rollouts_per_second": n / seconds,
        "provenance": stamp(definition, json.loads(sorted(computed)[0])),
        "computed_with_all": [json.loads(c) for c in sorted(computed)],
    }
    out = args.out.with_suffix(".json")
    out.write_text(json.dumps(summary, indent=2) + "\n")
    main = by_gamma[0]
    print(
        f"{spec.name}: {n:,} rollouts, p({main['gamma']:g} s) = {main['p']:.3e} "
        f"[{main['ci'][0]:.3e}, {main['ci'][1]:.3e}] ({main['n_hits']} hits); "
        f"wrote {out}"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario")
    parser.add_argument("--n", type=int, default=3_000_000, help="Rollouts in all.")
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--out", type=Path, required=True, help="Path stem.")
    parser.add_argument("--shard", default="0/1", help="I/K: chunks j = I mod K.")
    parser.add_argument("--batch-size", type=int, default=4096)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--gammas",
        type=lambda text: tuple(float(g) for g in text.split(",")),
        default=GAMMAS,
        help="Thresholds [s] to count hits at, comma-separated.",
    )
    parser.add_argument("--summarize", action="store_true")
    args = parser.parse_args(argv)
    i, _, k = args.shard.partition("/")
    args.shard = (int(i), int(k))
    if not 0 <= args.shard[0] < args.shard[1]:
        sys.exit(f"--shard {i}/{k}: need 0 <= I < K")
    torch.set_num_threads(args.threads)
    summarize(args) if args.summarize else simulate(args)


if __name__ == "__main__":
    main()
