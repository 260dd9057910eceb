"""Compare a scenario's initial conditions under P0 with the NGSIM I-80 pairs.

Issue 44, item 5: the initial-condition marginals of ``highway_default`` are
the paper's and were never checked against data. This draws ``n`` starts from
the scenario's own ``P0`` (:func:`avrisk.assembly.base_distribution`, unpacked
by :class:`~avrisk.scenario.ScenarioParams` and placed on the road by
:func:`avrisk.assembly.initial_state`) and compares, per quantity, its
quantiles (5/25/50/75/95%) with those of the shipped I-80 car-following pairs
(``avrisk/data/ngsim/i80_cf_pairs.parquet``, both periods, every 0.1 s row)
overall, per recording period and per speed band (a row is *congested* when
its leader drives below :data:`avrisk.learning.replay.CONGESTED_BELOW`) and
where the follower drives at speeds P0 gives the ego (``ego_speeds``), with
the two-sample Kolmogorov-Smirnov distance and how much of each side's range
(central 99%) the other covers.

Quantities (the slots' roles come from the spec: the nearest slot ahead of
the ego in its lane, the nearest behind, the rest by lane):

* ``speed.<slot>`` [m/s] -- each slot's initial speed; data: the follower's
  speed;
* ``gap.ego``, ``gap.behind`` [m] -- bumper-to-bumper gap of the ego to the
  slot ahead, of the slot behind to the ego; data: the pair's gap;
* ``headway.*`` [s] -- that gap over the following vehicle's speed (rows
  where it drives at least ``MIN_SPEED``);
* ``closing.*`` [m/s] -- follower's speed less leader's; data: ``dv``;
* ``ttc.*`` [s] -- gap over closing speed, where closing;
* ``offset.<slot>`` [m] -- centre-to-centre offset of a slot in another lane
  ahead of the ego. The pairs files do not hold every vehicle on the road, so
  the data side is *derived*, not observed: the offset to the nearest vehicle
  of a lane whose vehicles are spaced as the data's pairs (gap plus leader
  length) and phased independently of the ego, uniform on ``[-h/2, h/2]``.

Usage (P0 draws and the data only; no rollouts)::

    .venv/bin/python benchmarks/initial_conditions.py \
        --out benchmarks/results/initial_conditions.json
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray
from scipy import stats

from avrisk.assembly import base_distribution, initial_state, param_layout
from avrisk.learning.ngsim.loaders import load_i80_pairs
from avrisk.learning.ngsim.samples import CarFollowingPairs
from avrisk.learning.replay import BANDS, CONGESTED_BELOW
from avrisk.scenario import ScenarioParams, ScenarioSpec, load_spec

FloatArray = NDArray[np.float64]

QUANTILES = (5, 25, 50, 75, 95)
#: Percentiles bounding a sample's range for the coverage shares (robust to
#: the data's few extreme rows).
RANGE = (0.5, 99.5)
#: Slowest following speed [m/s] at which a time headway is taken.
MIN_SPEED = 1.0
#: Kinds whose range shares are taken on a log scale (heavy right tails).
LOG_KINDS = ("ttc",)
#: Draws of P0 per chunk (P0 has the 404 driver-network columns too).
CHUNK = 10_000
#: The pairs file's period names, as clock times.
PERIOD_NAMES = {"0400pm-0415pm": "16:00-16:15", "0500pm-0515pm": "17:00-17:15"}


def slot_roles(spec: ScenarioSpec) -> dict[str, int]:
    """Each non-ego slot's role by its place relative to the ego (slot 0).

    ``ahead``/``behind``: the nearest slot in front of / behind the ego in its
    lane; other slots ``left<k>``/``right<k>`` (``k`` lanes over; lane 0 is
    the rightmost; ``_<j>`` added for a second one), or ``same_<j>`` in the
    ego's lane but not nearest.
    """
    ego = spec.vehicles[0]
    roles: dict[str, int] = {}
    same = [j for j, v in enumerate(spec.vehicles) if j and v.lane == ego.lane]
    front = [j for j in same if spec.vehicles[j].offset > ego.offset]
    back = [j for j in same if spec.vehicles[j].offset <= ego.offset]
    if front:
        roles["ahead"] = min(front, key=lambda j: spec.vehicles[j].offset)
    if back:
        roles["behind"] = max(back, key=lambda j: spec.vehicles[j].offset)
    for j, v in enumerate(spec.vehicles[1:], start=1):
        if j in roles.values():
            continue
        lanes = v.lane - ego.lane
        name = f"left{lanes}" if lanes > 0 else f"right{-lanes}" if lanes else "same"
        roles[f"{name}_{j}" if name in roles or not lanes else name] = j
    return roles


def p0_states(spec: ScenarioSpec, n: int, seed: int) -> dict[str, FloatArray]:
    """Centre ``x`` [m], ``speed`` [m/s], ``length`` [m] of ``n`` starts, (n, A)."""
    p0, layout = base_distribution(spec), param_layout(spec)
    rng = np.random.default_rng(seed)
    parts = []
    for start in range(0, n, CHUNK):
        x = p0.sample(min(CHUNK, n - start), rng)
        state = initial_state(
            ScenarioParams.from_flat(x, layout), spec, dtype=torch.float64
        )
        parts.append([state.x.numpy(), state.speed.numpy(), state.length.numpy()])
    x, speed, length = (np.concatenate(p) for p in zip(*parts, strict=True))
    return {"x": x, "speed": speed, "length": length}


def following(
    gap: FloatArray, v_follower: FloatArray, v_leader: FloatArray
) -> dict[str, FloatArray]:
    """Gap [m], time headway [s], closing speed [m/s] and TTC [s] of a pair.

    All of the inputs' shape; headway NaN where the follower drives below
    ``MIN_SPEED``, TTC NaN where it does not close (``v_follower <= v_leader``).
    """
    closing = v_follower - v_leader
    slow = v_follower < MIN_SPEED
    return {
        "gap": gap,
        "headway": np.where(slow, np.nan, gap / np.where(slow, 1.0, v_follower)),
        "closing": closing,
        "ttc": np.where(closing > 0, gap / np.where(closing > 0, closing, 1.0), np.nan),
    }


def p0_quantities(spec: ScenarioSpec, n: int, seed: int) -> dict[str, FloatArray]:
    """The quantities of the module docstring under P0, each of shape (n,)."""
    st, roles = p0_states(spec, n, seed), slot_roles(spec)
    x, v, length = st["x"], st["speed"], st["length"]
    out = {f"speed.{r}": v[:, j] for r, j in {"ego": 0, **roles}.items()}
    pairs = {"ego": (roles.get("ahead"), 0), "behind": (0, roles.get("behind"))}
    for name, (lead, back) in pairs.items():
        if lead is None or back is None:
            continue
        gap = x[:, lead] - x[:, back] - 0.5 * (length[:, lead] + length[:, back])
        for k, values in following(gap, v[:, back], v[:, lead]).items():
            out[f"{k}.{name}"] = values
    for r, j in roles.items():
        if r not in ("ahead", "behind"):
            out[f"offset.{r}"] = x[:, j] - x[:, 0]
    return out


def data_quantities(
    pairs: CarFollowingPairs, rows: NDArray[np.bool_], seed: int
) -> dict[str, FloatArray]:
    """The data's side of each kind of quantity, over the selected rows, (R,).

    ``offset`` is derived (module docstring): ``(U - 1/2) h`` with ``U``
    uniform (``seed``) and ``h`` the row's gap plus leader length [m].
    """
    gap, vf, vl = pairs.gap[rows], pairs.v_follower[rows], pairs.v_leader[rows]
    spacing = gap + pairs.leader_length[rows]
    u = np.random.default_rng(seed).random(len(spacing))
    return {"speed": vf, **following(gap, vf, vl), "offset": (u - 0.5) * spacing}


def data_sets(
    pairs: CarFollowingPairs, ego_speeds: tuple[float, float]
) -> dict[str, NDArray[np.bool_]]:
    """Row masks: all, each period, each speed band, and ``ego_speeds``.

    Bands by the row's leader speed; ``ego_speeds``: the follower's speed
    inside P0's ego speed support ``(lo, hi)`` [m/s].
    """
    sets = {"all": np.ones(len(pairs.t), dtype=bool)}
    for period in np.unique(pairs.period):
        sets[PERIOD_NAMES.get(str(period), str(period))] = pairs.period == period
    congested = pairs.v_leader < CONGESTED_BELOW
    sets[BANDS[0]], sets[BANDS[1]] = congested, ~congested
    lo, hi = ego_speeds
    sets["ego_speeds"] = (pairs.v_follower >= lo) & (pairs.v_follower <= hi)
    return sets


def quantiles(values: FloatArray) -> dict[str, float]:
    """``n`` and the :data:`QUANTILES` of a sample's non-NaN values (``p5``...)."""
    values = values[~np.isnan(values)]
    q = np.percentile(values, QUANTILES)
    return {
        "n": len(values),
        **{f"p{k}": float(x) for k, x in zip(QUANTILES, q, strict=True)},
    }


def coverage(a: FloatArray, b: FloatArray, log: bool) -> dict[str, float]:
    """How much of ``b``'s range (central 99%) ``a``'s covers, and of its mass.

    ``log``: the range's length on a log scale (positive, heavy-tailed kinds).
    """
    lo_a, hi_a = np.percentile(a, RANGE)
    lo_b, hi_b = np.percentile(b, RANGE)
    scale = np.log if log else np.asarray
    overlap = max(0.0, scale(min(hi_a, hi_b)) - scale(max(lo_a, lo_b)))
    inside = np.mean((b >= lo_a) & (b <= hi_a))
    return {
        "range": float(overlap / (scale(hi_b) - scale(lo_b))),
        "mass": float(inside),
    }


def ks_bootstrap(
    p0: FloatArray, data: FloatArray, pair: NDArray[np.int64], n_boot: int, seed: int
) -> list[float]:
    """95% interval of the KS distance, resampling the data's pairs (clusters).

    The data's rows are 0.1 s apart within a pair and far from independent,
    so the pair, not the row, is the unit resampled; P0's sample is held.
    """
    _, cluster = np.unique(pair, return_inverse=True)
    order = np.argsort(data, kind="stable")
    grid = np.sort(np.concatenate([p0, data]))
    f_p0 = np.searchsorted(np.sort(p0), grid, side="right") / len(p0)
    below = np.searchsorted(data[order], grid, side="right")
    rng = np.random.default_rng(seed)
    n_clusters = cluster.max() + 1
    ks = np.empty(n_boot)
    for b in range(n_boot):
        counts = np.bincount(
            rng.integers(n_clusters, size=n_clusters), minlength=n_clusters
        )
        cum = np.concatenate([[0.0], np.cumsum(counts[cluster[order]])])
        ks[b] = np.abs(cum[below] / cum[-1] - f_p0).max()
    return [float(x) for x in np.percentile(ks, [2.5, 97.5])]


def comparison(p0: FloatArray, data: FloatArray, kind: str) -> dict[str, object]:
    """KS distance and the coverage shares both ways (non-NaN values)."""
    p0, data = p0[~np.isnan(p0)], data[~np.isnan(data)]
    log = kind in LOG_KINDS
    return {
        "ks": float(stats.ks_2samp(p0, data).statistic),
        "p0_covers_data": coverage(p0, data, log),
        "data_covers_p0": coverage(data, p0, log),
    }


def compare(
    scenario: str = "highway_default",
    n: int = 50_000,
    seed: int = 0,
    n_boot: int = 200,
    pairs: CarFollowingPairs | None = None,
) -> dict[str, object]:
    """The whole comparison as a JSON-ready dict (see the module docstring).

    Returns
    -------
    dict
        ``p0``: quantiles per quantity; ``data``: quantiles per set and kind;
        ``comparison``: per quantity and set, :func:`comparison`, with the
        pair-bootstrap interval ``ks_95`` (:func:`ks_bootstrap`) on ``all``.
    """
    spec = load_spec(scenario)
    pairs = load_i80_pairs() if pairs is None else pairs
    mine = p0_quantities(spec, n, seed)
    speed = spec.initial_for(0).speed
    sets = data_sets(pairs, (speed.lo, speed.lo + speed.scale))
    data = {name: data_quantities(pairs, rows, seed) for name, rows in sets.items()}
    table = {}
    for q, values in mine.items():
        kind = q.split(".")[0]
        table[q] = {s: comparison(values, d[kind], kind) for s, d in data.items()}
        ok = ~np.isnan(data["all"][kind])
        table[q]["all"]["ks_95"] = ks_bootstrap(
            values[~np.isnan(values)], data["all"][kind][ok], pairs.pair_id[ok],
            n_boot, seed,
        )  # fmt: skip
    return {
        "scenario": spec.name,
        "n_p0": n,
        "seed": seed,
        "n_boot": n_boot,
        "data_rows": {k: int(v.sum()) for k, v in sets.items()},
        "data_pairs": {k: len(np.unique(pairs.pair_id[v])) for k, v in sets.items()},
        "congested_below": CONGESTED_BELOW,
        "min_speed_headway": MIN_SPEED,
        "range_percentiles": list(RANGE),
        "log_range_kinds": list(LOG_KINDS),
        "p0": {q: quantiles(values) for q, values in mine.items()},
        "data": {s: {k: quantiles(v) for k, v in d.items()} for s, d in data.items()},
        "comparison": table,
    }


def _row(cells: Sequence[object]) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def quantile_table(result: dict) -> str:
    """Markdown: quantiles of every P0 quantity, then of the data per set."""
    head = ["quantity", "set", *(f"p{k}" for k in QUANTILES)]
    lines = [_row(head), _row(["---"] * len(head))]
    for q, v in result["p0"].items():
        lines.append(_row([q, "P0", *(f"{v[f'p{k}']:.1f}" for k in QUANTILES)]))
    kinds = result["data"]["all"].keys()
    for kind in kinds:
        for s, d in result["data"].items():
            v = d[kind]
            label = f"{kind} (derived)" if kind == "offset" else kind
            cells = [label, s, *(f"{v[f'p{k}']:.1f}" for k in QUANTILES)]
            lines.append(_row(cells))
    return "\n".join(lines)


def ks_table(result: dict) -> str:
    """Markdown: KS distance per quantity and data set; coverage against all."""
    sets = list(result["data"])
    short = {BANDS[0]: "cong.", BANDS[1]: "flow.", "ego_speeds": "egoV"}
    head = ["quantity", "KS all [95%]", *(short.get(s, s[:5]) for s in sets[1:])]
    head += ["P0:d", "d:P0"]
    lines = [_row(head), _row(["---"] * len(head))]
    for q, per_set in result["comparison"].items():
        everything = per_set["all"]
        lo, hi = everything["ks_95"]
        ks = [f"{everything['ks']:.2f} [{lo:.2f},{hi:.2f}]"]
        ks += [f"{per_set[s]['ks']:.2f}" for s in sets[1:]]
        both = [everything[k]["range"] for k in ("p0_covers_data", "data_covers_p0")]
        lines.append(_row([q, *ks, *(f"{c:.2f}" for c in both)]))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> dict:
    """Run the comparison, write ``--out`` (JSON) and print both tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway_default")
    parser.add_argument("--n", type=int, default=50_000, help="draws of P0")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--boot", type=int, default=200, help="pair resamples")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    result = compare(args.scenario, args.n, args.seed, args.boot)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(quantile_table(result))
    print()
    print(ks_table(result))
    return result


if __name__ == "__main__":
    main()
