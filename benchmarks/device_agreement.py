"""Do two devices give the same answer? The same naive draws, row by row.

Simulates fixed draws of a scenario's P0 in chunks on one device and records,
per chunk, the hits at several thresholds, the crashes, and every *near* row
(``f <= --near``, default 1 s) with its ``f``, crash flag and contact. Run it
once per device (or per torch build) into its own folder, then ``compare``
the folders chunk by chunk and row by row: a device that rounds differently
shows up as rows whose ``f`` moved, and an answer that differs as rows that
hit on one side only. A rate of 2e-4 is a few hundred rows in millions, so an
agreement check on a thousand rollouts cannot see it; this one can.

The draws are those of issue 42's GPU reference of ``highway_idm``: chunk
``k`` holds ``--chunk-size`` rows, its X from ``p0.sample(chunk_size,
chunk_rng(seed, 0, k))`` and its rollout seeds from ``sample_seeds(seed, 0,
arange(k * chunk_size, (k + 1) * chunk_size))``. Rows are independent of the
batch they are simulated in (each rollout has its own seed), so
``--sub-batch`` and ``--group`` (chunks simulated together) only set memory
and speed. With ``--chunk-size 8192`` the chunks are those of
``benchmarks/reference.py`` for the same seed.

Usage (chunks as files under ``OUT``; rerunning skips the chunks done;
``--shard I/K`` does chunks ``k = I mod K`` for K processes side by side)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/device_agreement.py simulate \\
        highway_idm --seed 2026 --chunks 0-13 --device cpu --out runs/idm_cpu
    python3 benchmarks/device_agreement.py simulate highway_idm --seed 2026 \\
        --chunks 0-13 --device cuda --sub-batch 262144 --out runs/idm_cuda
    .venv/bin/python benchmarks/device_agreement.py compare runs/idm_cpu runs/idm_cuda
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from avrisk.assembly import ScenarioSimulator, SimulationObjective, base_distribution
from avrisk.pipeline.provenance import stamp
from avrisk.rare.intervals import clopper_pearson
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import load_spec

#: Thresholds [s] counted.
GAMMAS = (0.1, 0.3, 0.5, 1.0)
#: Names of the simulator's contact codes (``RolloutResult.contact``).
MECHANISMS = ("no_contact", "rear_end", "hit_from_behind", "side")
SCHEMA = "avrisk.device_agreement/1"


def chunk_draws(
    spec, seed: int, chunk: int, chunk_size: int
) -> tuple[np.ndarray, np.ndarray]:
    """X (chunk_size, D) and int64 seeds (chunk_size,) of one chunk."""
    x = base_distribution(spec).sample(chunk_size, chunk_rng(seed, 0, chunk))
    ids = np.arange(chunk * chunk_size, (chunk + 1) * chunk_size)
    return x, sample_seeds(seed, 0, ids)


def simulate_rows(
    sim: ScenarioSimulator, x: np.ndarray, seeds: np.ndarray, sub_batch: int
) -> dict[str, np.ndarray]:
    """``f`` (float32 as float64), ``crash``, ``contact`` of every row."""
    parts: dict[str, list[np.ndarray]] = {"f": [], "crash": [], "contact": []}
    with torch.no_grad():
        for start in range(0, len(x), sub_batch):
            res = sim.rollout(
                x[start : start + sub_batch], seeds[start : start + sub_batch]
            )
            parts["f"].append(res.f.cpu().numpy().astype(np.float64))
            parts["crash"].append(res.crash.cpu().numpy())
            parts["contact"].append(res.contact.cpu().numpy().astype(np.int64))
    return {name: np.concatenate(chunks) for name, chunks in parts.items()}


def chunk_record(rows: dict[str, np.ndarray], near: float) -> dict:
    """Counts at every threshold and the near rows of one simulated chunk."""
    f, crash = rows["f"], rows["crash"]
    index = np.flatnonzero(f <= near)
    return {
        "n": len(f),
        "failed": int(np.isnan(f).sum()),
        "crashes": int(crash.sum()),
        "hits": {f"{g:g}": int((f <= g).sum()) for g in GAMMAS},
        "near": {
            "row": index.tolist(),
            "f": f[index].tolist(),
            "crash": crash[index].astype(int).tolist(),
            "contact": rows["contact"][index].tolist(),
        },
    }


def _chunk_path(out: Path, chunk: int) -> Path:
    return out / f"chunk_{chunk:04d}.json"


def _parse_range(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def simulate(args: argparse.Namespace) -> None:
    spec = load_spec(args.scenario)
    objective = SimulationObjective(spec, device=args.device)
    sim = objective.simulator
    i, _, k = args.shard.partition("/")
    todo = [c for c in _parse_range(args.chunks) if c % int(k) == int(i)]
    args.out.mkdir(parents=True, exist_ok=True)
    todo = [c for c in todo if not _chunk_path(args.out, c).is_file()]
    recorded = {  # the same for every chunk: hashed once
        "defines_p": objective.definition(),
        "computed_with": objective.computed_with(),
    }
    for first in range(0, len(todo), args.group):
        group = todo[first : first + args.group]
        start = time.perf_counter()
        draws = [chunk_draws(spec, args.seed, c, args.chunk_size) for c in group]
        x, seeds = (np.concatenate(part) for part in zip(*draws, strict=True))
        rows = simulate_rows(sim, x, seeds, args.sub_batch)
        seconds = (time.perf_counter() - start) / len(group)
        for j, chunk in enumerate(group):
            mine = slice(j * args.chunk_size, (j + 1) * args.chunk_size)
            record = {
                "schema": SCHEMA,
                "scenario": spec.name,
                "seed": args.seed,
                "chunk": chunk,
                "chunk_size": args.chunk_size,
                "sub_batch": args.sub_batch,
                "near_threshold": args.near,
                **recorded,
                "seconds": seconds,
                **chunk_record({k: v[mine] for k, v in rows.items()}, args.near),
            }
            path = _chunk_path(args.out, chunk)
            tmp = path.with_suffix(".tmp")
            tmp.write_text(json.dumps(record) + "\n")
            os.replace(tmp, path)
        hits = int(np.count_nonzero(rows["f"] <= GAMMAS[0]))
        print(
            f"chunks {group[0]}-{group[-1]}: {args.chunk_size / seconds:.0f} "
            f"rollouts/s, hits at {GAMMAS[0]:g} s: {hits}",
            file=sys.stderr,
            flush=True,
        )


def read_chunks(source: Path) -> dict[int, dict]:
    """Recorded chunks of a folder (``chunk_*.json``) or a ``.jsonl`` of them."""
    if source.is_file():
        texts = source.read_text().splitlines()
    else:
        texts = [path.read_text() for path in sorted(source.glob("chunk_*.json"))]
    chunks = {}
    for text in texts:
        record = json.loads(text)
        if record.get("schema") != SCHEMA:
            sys.exit(f"{source}: not {SCHEMA} records")
        chunks[record["chunk"]] = record
    if not chunks:
        sys.exit(f"{source}: no recorded chunks")
    return chunks


def _near_rows(record: dict) -> dict[int, tuple[float, int]]:
    """Row index -> (f, crash) of one chunk's near rows."""
    near = record["near"]
    return {
        r: (f, c) for r, f, c in zip(near["row"], near["f"], near["crash"], strict=True)
    }


def compare_chunk(a: dict, b: dict) -> dict:
    """Row-by-row agreement of one chunk simulated twice.

    Only rows near on at least one side are known; a row near on one side
    only is a disagreement at every threshold it crosses.
    """
    near = min(a["near_threshold"], b["near_threshold"])
    rows_a, rows_b = _near_rows(a), _near_rows(b)
    both = sorted(set(rows_a) & set(rows_b))
    diffs = [abs(rows_a[r][0] - rows_b[r][0]) for r in both]
    differing = [r for r in both if rows_a[r][0] != rows_b[r][0]]
    one_side = sorted(
        r
        for r in set(rows_a) ^ set(rows_b)
        if min(rows_a.get(r, (math.inf,))[0], rows_b.get(r, (math.inf,))[0]) <= near
    )
    crash_diff = [r for r in both if rows_a[r][1] != rows_b[r][1]]
    hits_only = {
        f"{g:g}": [
            sum(
                1
                for r, (f, _) in mine.items()
                if f <= g and theirs.get(r, (math.inf,))[0] > g
            )
            for mine, theirs in ((rows_a, rows_b), (rows_b, rows_a))
        ]
        for g in GAMMAS
        if g <= near
    }
    return {
        "chunk": a["chunk"],
        "n": a["n"],
        "hits": {key: [a["hits"][key], b["hits"][key]] for key in a["hits"]},
        "crashes": [a["crashes"], b["crashes"]],
        "near_rows_both": len(both),
        "near_rows_differing_f": len(differing),
        "near_rows_one_side": len(one_side),
        "crash_disagreements": len(crash_diff),
        "max_abs_f_diff_s": max(diffs, default=0.0),
        "hits_on_one_side_only": hits_only,
    }


def compare(args: argparse.Namespace) -> None:
    a, b = read_chunks(args.a), read_chunks(args.b)
    for key in ("scenario", "seed", "chunk_size", "defines_p"):
        va, vb = next(iter(a.values()))[key], next(iter(b.values()))[key]
        if va != vb:
            sys.exit(f"{key} differs: {va} against {vb}: not the same draws")
    common = sorted(set(a) & set(b))
    per_chunk = [compare_chunk(a[c], b[c]) for c in common]
    totals = {
        "chunks": len(common),
        "n": sum(c["n"] for c in per_chunk),
        "hits": {
            key: [sum(c["hits"][key][s] for c in per_chunk) for s in (0, 1)]
            for key in per_chunk[0]["hits"]
        },
        "crashes": [sum(c["crashes"][s] for c in per_chunk) for s in (0, 1)],
        "near_rows_differing_f": sum(c["near_rows_differing_f"] for c in per_chunk),
        "near_rows_one_side": sum(c["near_rows_one_side"] for c in per_chunk),
        "crash_disagreements": sum(c["crash_disagreements"] for c in per_chunk),
        "max_abs_f_diff_s": max(c["max_abs_f_diff_s"] for c in per_chunk),
    }
    sides = [
        json.dumps(next(iter(side.values()))["computed_with"], sort_keys=True)
        for side in (a, b)
    ]
    print(f"A = {args.a}: {sides[0]}\nB = {args.b}: {sides[1]}")
    print(
        f"{'chunk':>5} {'rows':>8} "
        + " ".join(f"{'f<=' + k:>13}" for k in totals["hits"])
    )
    for c in per_chunk:
        cells = " ".join(f"{h[0]:>6}/{h[1]:<6}" for h in c["hits"].values())
        print(f"{c['chunk']:>5} {c['n']:>8} {cells}")
    cells = " ".join(f"{h[0]:>6}/{h[1]:<6}" for h in totals["hits"].values())
    print(f"{'all':>5} {totals['n']:>8} {cells}")
    print(
        f"crashes {totals['crashes'][0]}/{totals['crashes'][1]}; near rows whose f "
        f"differs: {totals['near_rows_differing_f']} (largest |df| "
        f"{totals['max_abs_f_diff_s']:.3g} s); near on one side only: "
        f"{totals['near_rows_one_side']}; crash disagreements: "
        f"{totals['crash_disagreements']}"
    )
    if args.json:
        args.json.write_text(
            json.dumps(
                {
                    "a": str(args.a),
                    "b": str(args.b),
                    "computed_with": sides,
                    "totals": totals,
                    "per_chunk": per_chunk,
                },
                indent=1,
            )
            + "\n"
        )


def near_draws(
    spec, chunks: dict[int, dict], below: float, n_rows: int
) -> tuple[list[tuple[float, int, int]], np.ndarray, np.ndarray]:
    """X and seeds of up to ``n_rows`` recorded rows with ``f <= below``.

    The rows are spread evenly over their sorted recorded ``f`` (all of them
    when there are no more than ``n_rows``). Returns the picked ``(f, chunk,
    row)`` triples, X (R, D) and int64 seeds (R,).
    """
    first = next(iter(chunks.values()))
    near = sorted(
        (f, record["chunk"], row)
        for record in chunks.values()
        for row, (f, _) in _near_rows(record).items()
        if f <= below
    )
    spread = np.unique(np.linspace(0, len(near) - 1, n_rows).round().astype(int))
    picked = sorted(  # in the order drawn: chunk by chunk, row by row
        (near[i] for i in spread) if near else [], key=lambda item: item[1:]
    )
    x, seeds = [], []
    for chunk in sorted({c for _, c, _ in picked}):  # each chunk drawn once
        rows = [r for _, c, r in picked if c == chunk]
        chunk_x, chunk_seeds = chunk_draws(
            spec, first["seed"], chunk, first["chunk_size"]
        )
        x.extend(chunk_x[rows])
        seeds.extend(chunk_seeds[rows])
    return picked, np.array(x), np.array(seeds, dtype=np.int64)


def recheck(args: argparse.Namespace) -> None:
    """Simulate a folder's near rows again on this device and compare ``f``.

    Every recorded row with ``f <= --below`` (a GPU run's hits, say) is drawn
    again from its chunk and simulated here; prints how many keep their ``f``
    bit for bit, the largest difference, and the hits at each threshold on
    both sides. Rows that were not near on the recording device are not
    simulated, so this checks that its hits are hits here, not the reverse
    (``compare`` on whole chunks does both).
    """
    chunks = read_chunks(args.source)
    first = next(iter(chunks.values()))
    spec = load_spec(first["scenario"])
    objective = SimulationObjective(spec, device=args.device)
    if objective.definition() != first["defines_p"]:
        sys.exit(f"{args.source} was simulated for another definition of p")
    picked, x, seeds = near_draws(spec, chunks, args.below, 10**9)
    f_then = np.array([f for f, _, _ in picked])
    f_now = simulate_rows(objective.simulator, x, seeds, args.sub_batch)["f"]
    diff = np.abs(f_now - f_then)
    summary = {
        "source": str(args.source),
        "then": first["computed_with"],
        "now": objective.computed_with(),
        "rows": len(picked),
        "rows_identical": int(np.sum(f_now == f_then)),
        "max_abs_f_diff_s": float(diff.max(initial=0.0)),
        "hits_then_now": {
            f"{g:g}": [int(np.sum(f_then <= g)), int(np.sum(f_now <= g))]
            for g in GAMMAS
            if g <= args.below
        },
    }
    print(json.dumps(summary))


def pooled_reference(args: argparse.Namespace) -> None:
    """A naive reference pooled from folders of simulated chunks.

    Each folder holds one seed's chunks (``simulate``'s ``--out``); seeds
    differ, so the draws are independent and the chunks pool into one naive
    sample. Any set of whole chunks counts: which chunks a process finished
    before its time ran out does not depend on their outcomes. Hits come
    from the recorded near rows, so thresholds above the folders' ``--near``
    are left out. Writes ``avrisk.reference/1`` (as ``reference.py
    --summarize`` does: per threshold the hits, ``p``, its standard error, the
    exact 95% interval and the hits by contact), readable by
    ``coverage.py table``.
    """
    records = [r for path in args.folders for r in read_chunks(path).values()]
    seeds = sorted({r["seed"] for r in records})
    if len(seeds) != len(args.folders):
        sys.exit("each folder must hold one seed, and no seed two folders")
    definitions = {json.dumps(r["defines_p"], sort_keys=True) for r in records}
    if len({r["scenario"] for r in records}) != 1 or len(definitions) != 1:
        sys.exit("the folders were simulated for different definitions of p")
    near = min(r["near_threshold"] for r in records)
    n = sum(r["n"] for r in records)
    by_gamma = []
    for g in sorted(g for g in args.gammas if g <= near):
        mech = dict.fromkeys(MECHANISMS, 0)
        for r in records:
            for f, contact in zip(r["near"]["f"], r["near"]["contact"], strict=True):
                if f <= g:
                    mech[MECHANISMS[contact]] += 1
        k = sum(mech.values())
        by_gamma.append(
            {
                "gamma": g,
                "n_hits": k,
                "p": k / n,
                "stderr": math.sqrt(k / n * (1 - k / n) / n),
                "ci": list(clopper_pearson(k, n)),
                "hits_by_contact": mech,
            }
        )
    computed = sorted({json.dumps(r["computed_with"], sort_keys=True) for r in records})
    summary = {
        "schema": "avrisk.reference/1",
        "scenario": records[0]["scenario"],
        "command": "benchmarks/device_agreement.py simulate "
        f"{records[0]['scenario']} --seed S (S = {', '.join(map(str, seeds))}), "
        f"pooled by device_agreement.py reference",
        "seed": "+".join(map(str, seeds)),
        "n": n,
        "n_failed": sum(r["failed"] for r in records),
        "chunks": len(records),
        "crashes": sum(r["crashes"] for r in records),
        "by_gamma": by_gamma,
        "provenance": stamp(records[0]["defines_p"], json.loads(computed[0])),
        "computed_with_all": [json.loads(c) for c in computed],
    }
    args.out.write_text(json.dumps(summary, indent=2) + "\n")
    main = by_gamma[0]
    print(
        f"{summary['scenario']}: {n:,} rollouts, p({main['gamma']:g} s) = "
        f"{main['p']:.3e} [{main['ci'][0]:.3e}, {main['ci'][1]:.3e}] "
        f"({main['n_hits']} hits); wrote {args.out}"
    )


def fixture(args: argparse.Namespace) -> None:
    """Write the replay test's rows: near rows, simulated again here.

    ``--rows`` rows of ``--source``'s chunks with ``f <= --below``, evenly
    spread over their sorted ``f`` (crashes and near misses alike), their X
    and seeds, and ``f``, crash and contact as this device simulates them now.
    """
    chunks = read_chunks(args.source)
    first = next(iter(chunks.values()))
    spec = load_spec(first["scenario"])
    objective = SimulationObjective(spec, device=args.device)
    picked, x, seeds = near_draws(spec, chunks, args.below, args.rows)
    rows = simulate_rows(objective.simulator, x, seeds, len(x))
    args.out.write_text(
        json.dumps(
            {
                "scenario": spec.name,
                "defines_p": objective.definition(),
                "computed_with": objective.computed_with(),
                "drawn_as": {
                    "seed": first["seed"],
                    "chunk_size": first["chunk_size"],
                    "chunk_row": [[c, r] for _, c, r in picked],
                },
                "x": x.tolist(),
                "seeds": seeds.tolist(),
                "f": rows["f"].tolist(),
                "crash": rows["crash"].astype(int).tolist(),
                "contact": rows["contact"].tolist(),
            }
        )
        + "\n"
    )
    print(f"wrote {len(x)} rows to {args.out}", file=sys.stderr)


def against_reference(args: argparse.Namespace) -> None:
    """Each chunk's hits against ``benchmarks/reference.py``'s record of it."""
    mine = read_chunks(args.folder)
    recorded = {}
    for path in args.lines:
        for text in path.read_text().splitlines():
            line = json.loads(text)
            recorded[line["chunk"]] = line
    common = sorted(set(mine) & set(recorded))
    differ = []
    for c in common:
        theirs = {k: sum(v.values()) for k, v in recorded[c]["hits"].items()}
        if any(theirs[k] != n for k, n in mine[c]["hits"].items()):
            differ.append(c)
    totals = {
        key: sum(mine[c]["hits"][key] for c in common)
        for key in mine[common[0]]["hits"]
    }
    print(
        f"{len(common)} chunks ({sum(mine[c]['n'] for c in common):,} rollouts) in "
        f"both: hits {totals}; chunks whose hits differ: {differ or 'none'}"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("simulate", help="Simulate chunks of draws on one device.")
    run.add_argument("scenario")
    run.add_argument("--seed", type=int, default=2026)
    run.add_argument("--chunks", default="0-13", help="First-last chunk index.")
    run.add_argument("--chunk-size", type=int, default=262_144)
    run.add_argument("--sub-batch", type=int, default=8192)
    run.add_argument(
        "--group", type=int, default=1, help="Chunks simulated together (a GPU batch)."
    )
    run.add_argument("--device", default="cpu")
    run.add_argument(
        "--near", type=float, default=1.0, help="Rows kept: f <= NEAR [s]."
    )
    run.add_argument("--shard", default="0/1", help="I/K: chunks k = I mod K.")
    run.add_argument("--threads", type=int, default=1)
    run.add_argument("--out", type=Path, required=True)
    cmp = sub.add_parser("compare", help="Compare two folders chunk by chunk.")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    cmp.add_argument("--json", type=Path, help="Also write the comparison here.")
    fix = sub.add_parser("fixture", help="Write the replay test's rows.")
    fix.add_argument("source", type=Path, help="A folder of simulated chunks.")
    fix.add_argument("--out", type=Path, required=True)
    fix.add_argument(
        "--below", type=float, default=0.5, help="Rows with f <= this [s]."
    )
    fix.add_argument("--rows", type=int, default=64)
    fix.add_argument("--device", default="cpu")
    ref = sub.add_parser(
        "against-reference", help="Hits per chunk against reference.py's lines."
    )
    ref.add_argument("folder", type=Path, help="Chunks of --chunk-size 8192.")
    ref.add_argument("lines", type=Path, nargs="+", help="OUT.shard*.chunks.jsonl")
    chk = sub.add_parser(
        "recheck", help="Simulate a folder's near rows again here; compare f."
    )
    chk.add_argument("source", type=Path, help="A folder of simulated chunks.")
    chk.add_argument("--below", type=float, default=0.5, help="Rows with f <= this.")
    chk.add_argument("--sub-batch", type=int, default=8192)
    chk.add_argument("--device", default="cpu")
    pool = sub.add_parser(
        "reference", help="A naive reference pooled from folders of seeds."
    )
    pool.add_argument("folders", type=Path, nargs="+", help="One seed each.")
    pool.add_argument(
        "--gammas",
        type=lambda text: [float(g) for g in text.split(",")],
        default=[0.1, 0.14, 0.2, 0.3, 0.5],
        help="Thresholds [s], comma-separated.",
    )
    pool.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    torch.set_num_threads(getattr(args, "threads", 1))
    commands = {
        "simulate": simulate,
        "compare": compare,
        "fixture": fixture,
        "against-reference": against_reference,
        "recheck": recheck,
        "reference": pooled_reference,
    }
    commands[args.command](args)


if __name__ == "__main__":
    main()
