"""Lane changes of the learned drivers: closed-loop calibration, then evaluation.

The learned drivers change lanes through the layer of
:mod:`avrisk.agents.drivers.lane_change`. Everything is measured with one
detector (:mod:`avrisk.learning.lane_changes`) on the US-101 vehicles and on
the simulator's traces alike, in random six-lane traffic (6 vehicles per scene,
the scenes of ``benchmarks/driver_realism.py`` part B), every vehicle driven by
the driver network with ``xi ~ N(mu0, Sigma0)`` per scene.

Calibration (``--calibrate``; US-101 *training* vehicles and simulated
calibration scenes only):

1. ``offset_clip``: among a few values, the one whose manoeuvres' median
   duration and median peak lateral speed are together closest (sum of
   relative errors) to the training vehicles';
2. gap acceptance ``(min_gap, min_ttc)``: on a grid, the setting with the
   fewest *lane-change collisions* (a collision onset while one of the two
   vehicles is changing lanes, or within 1 s after) among those whose rate is
   within 5% of the grid's highest (the least strict setting on a tie): as
   safe as the grid allows while keeping the rate. The data cannot show gap
   acceptance (the US-101 vehicles come without their neighbours);
3. the hazard: a desire waits for a gap and none arrives during a manoeuvre,
   so the simulated rate falls short of the hazard; the hazard is scaled once
   by ``train rate / simulated rate``.

Evaluation (fresh scenes, another seed): lane changes per vehicle-hour with
their exact Poisson interval against the *held-out* US-101 vehicles (target:
within +-30%) and IDM+MOBIL (same scenes), duration and peak lateral speed,
and collisions per vehicle-hour with the layer on and off; then the bundled
``highway_default`` against ``highway_lane_changes`` on the same draws of ``X``
and seeds (how many environment vehicles change lanes in a rollout, and the
ego's crash rate and safety measure).

Usage::

    .venv/bin/python benchmarks/lane_change_realism.py --calibrate
    .venv/bin/python benchmarks/lane_change_realism.py   # shipped defaults only
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from typing import Any

import numpy as np
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.lane_change import LaneChangeParams, LaneChangingDriver
from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
from avrisk.agents.idm import IDMDriver
from avrisk.learning.lane_changes import (
    LaneChanges,
    detect_lane_changes,
    exposure_seconds,
    poisson_rate_interval,
)
from avrisk.learning.simulated_demonstrations import random_highway_scenes
from avrisk.learning.us101_lane_changes import (
    LaneChangeStatistics,
    lane_change_statistics,
    load_lane_change_tables,
    split_statistics,
)
from avrisk.safety import MinTTC
from avrisk.scenario import xi_base_family
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.collision import pairwise_overlap

DT = 0.1
N_VEHICLES = 6
#: A collision this soon after a change ends still counts as the change's [s].
AFTER_CHANGE = 1.0
CLIPS = (0.4, 0.5, 0.6, 0.7)
GAP_GRID = (
    (0.0, 0.0),
    (2.0, 2.0),
    (4.0, 2.0),
    (4.0, 4.0),
    (8.0, 6.0),
    (12.0, 8.0),
    (16.0, 10.0),
)
#: Gap acceptance may cost at most this share of the grid's highest rate.
RATE_LOSS = 0.05


class Scenes:
    """Random six-lane scenes, their ``xi`` draws and seeds (one per scene)."""

    def __init__(self, n: int, seed: int, horizon: float) -> None:
        rng = np.random.default_rng(seed)
        self.road = Road()
        self.init, self.idm = random_highway_scenes(n, N_VEHICLES, self.road, rng)
        fam = xi_base_family(load_xi_prior())
        self.xi = torch.as_tensor(fam.sample(n, rng), dtype=torch.float32)
        self.seeds = torch.arange(n, dtype=torch.int64) + 1_000_003 * seed
        self.sim = Simulator(
            self.road, SimConfig(horizon=horizon), measure=MinTTC(n_rays=1)
        )

    def run(self, actor: Any, params: list) -> Any:
        """The traces of every scene driven by ``actor`` (all vehicles)."""
        res = self.sim.run(
            self.init, [actor], self.seeds, params=params, record_trace=True
        )
        return res.trace


def collision_onsets(trace: Any, init: VehicleState) -> np.ndarray:
    """``(scene, i, j, frame)`` of every new overlap of vehicles ``i < j``."""
    rows, prev = [], None
    for k in range(trace.x.shape[1]):
        st = VehicleState(
            trace.x[:, k],
            trace.y[:, k],
            trace.heading[:, k],
            trace.speed[:, k],
            init.length,
            init.width,
        )
        now = pairwise_overlap(st, *st.cos_sin) & trace.alive[:, k, None, None]
        if prev is not None:
            b, i, j = torch.nonzero(torch.triu(now & ~prev, diagonal=1), as_tuple=True)
            rows += [
                (int(bb), int(ii), int(jj), k)
                for bb, ii, jj in zip(b, i, j, strict=True)
            ]
        prev = now
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


def measure(trace: Any, init: VehicleState, lane_width: float, noise: float) -> dict:
    """Lane changes, exposure, collisions and lane-change collisions of traces."""
    y = trace.y.numpy()  # (B, T+1, A)
    b, frames, a = y.shape
    changes = LaneChanges.concat(
        [
            detect_lane_changes(
                y[i, :, j],
                DT,
                lane_width=lane_width,
                noise_speed=noise,
                track=i * a + j,
            )
            for i in range(b)
            for j in range(a)
        ]
    )
    hours = float(exposure_seconds(frames, DT)) * b * a / 3600.0
    driven_hours = (frames - 1) * DT * b * a / 3600.0
    onsets = collision_onsets(trace, init)
    after = round(AFTER_CHANGE / DT)
    lc_hits = 0
    for scene, i, j, k in onsets:
        for v in (i, j):
            own = changes.track == scene * a + v
            if np.any((changes.start[own] <= k) & (k <= changes.end[own] + after)):
                lc_hits += 1
                break
    return {
        "changes": changes,
        "vehicles": b * a,
        "hours": hours,
        "driven_hours": driven_hours,
        "collisions": len(onsets),
        "lc_collisions": lc_hits,
    }


def statistics(m: dict) -> LaneChangeStatistics:
    """Rate and profile of the changes of :func:`measure`."""
    ch = m["changes"]
    return lane_change_statistics(
        m["vehicles"],
        m["hours"] * 3600.0,
        ch.direction,
        ch.duration,
        ch.peak_lateral_speed,
    )


def layer(net, scenes: Scenes, params: LaneChangeParams, stochastic=True):
    """The lane-changing learned drivers of every vehicle."""
    every = torch.ones(N_VEHICLES, dtype=torch.bool)
    inner = LearnedDriver(net, controlled=every, stochastic=stochastic)
    return LaneChangingDriver(inner, scenes.road, params)


def calibrate(net, scenes: Scenes, train: LaneChangeStatistics, noise: float):
    """The three calibration steps of the module docstring; settings and log."""
    log: dict[str, Any] = {"clip": [], "gaps": []}
    base = LaneChangeParams(rate=train.rate / 3600.0)

    def measured(p: LaneChangeParams) -> dict:
        trace = scenes.run(layer(net, scenes, p), [scenes.xi])
        return measure(trace, scenes.init, scenes.road.lane_width, noise)

    best = None
    for clip in CLIPS:
        m = measured(dataclasses.replace(base, offset_clip=clip))
        s = statistics(m)
        err = abs(s.duration_q50 / train.duration_q50 - 1) + abs(
            s.peak_q50 / train.peak_q50 - 1
        )
        log["clip"].append({"offset_clip": clip, "error": err, **s.to_dict()})
        print(f"  clip {clip}: {fmt(s)}, profile error {err:.3f}", flush=True)
        if best is None or err < best[0]:
            best = (err, clip)
    assert best is not None
    base = dataclasses.replace(base, offset_clip=best[1])
    for gap, ttc in GAP_GRID:
        m = measured(dataclasses.replace(base, min_gap=gap, min_ttc=ttc))
        s = statistics(m)
        row = {
            "min_gap": gap,
            "min_ttc": ttc,
            "lc_collisions": m["lc_collisions"],
            "collisions": m["collisions"],
            "driven_hours": m["driven_hours"],
            **s.to_dict(),
        }
        log["gaps"].append(row)
        print(
            f"  gap {gap} m, ttc {ttc} s: {fmt(s)}, lane-change collisions "
            f"{m['lc_collisions']}, all collisions {m['collisions']}",
            flush=True,
        )
    top = max(row["rate"] for row in log["gaps"])
    kept = [row for row in log["gaps"] if row["rate"] >= (1 - RATE_LOSS) * top]
    best_row = min(kept, key=lambda row: row["lc_collisions"])  # first: least strict
    gap, ttc, achieved = best_row["min_gap"], best_row["min_ttc"], best_row["rate"]
    rate = train.rate * train.rate / achieved
    log["hazard"] = {"train_rate": train.rate, "achieved": achieved, "hazard": rate}
    print(f"  hazard {rate:.1f}/veh-h (train {train.rate:.1f}, got {achieved:.1f})")
    return (
        dataclasses.replace(base, min_gap=gap, min_ttc=ttc, rate=rate / 3600.0),
        log,
    )


def fmt(s: LaneChangeStatistics) -> str:
    """Rate [interval], duration and peak medians of a statistics row."""
    return (
        f"{s.rate:.1f} [{s.rate_low:.1f}, {s.rate_high:.1f}] /veh-h, duration "
        f"p10/50/90 {s.duration_q10:.1f}/{s.duration_q50:.1f}/{s.duration_q90:.1f} "
        f"s, peak |vy| p10/50/90 {s.peak_q10:.2f}/{s.peak_q50:.2f}/{s.peak_q90:.2f} "
        "m/s"
    )


def evaluate(net, scenes: Scenes, params: LaneChangeParams, noise: float) -> dict:
    """Measurements of the drivers compared, on the evaluation scenes."""
    drivers = {
        "learned + lane changes (sampled actions)": (
            layer(net, scenes, params),
            [scenes.xi],
        ),
        "learned + lane changes (mean actions)": (
            layer(net, scenes, params, stochastic=False),
            [scenes.xi],
        ),
        "learned, no lane changes (sampled actions)": (
            LearnedDriver(net, controlled=torch.ones(N_VEHICLES, dtype=torch.bool)),
            [scenes.xi],
        ),
        "IDM+MOBIL": (IDMDriver(scenes.idm, scenes.road), [None]),
    }
    out = {}
    for name, (actor, params_) in drivers.items():
        t0 = time.perf_counter()
        m = measure(
            scenes.run(actor, params_), scenes.init, scenes.road.lane_width, noise
        )
        out[name] = m
        print(f"  {name}: {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def table(human: LaneChangeStatistics, results: dict) -> str:
    """The markdown table of the evaluation."""
    lines = [
        "| drivers | lane changes [1/veh-h] (95% CI) | vs held-out | duration "
        "p10/50/90 [s] | peak lateral speed p10/50/90 [m/s] | collisions "
        "[1/veh-h] | lane-change collisions [1/veh-h] (95% CI) |",
        "|---|---|---|---|---|---|---|",
        f"| human, held-out US-101 ({human.hours:.2f} veh-h) | {human.rate:.1f} "
        f"[{human.rate_low:.1f}, {human.rate_high:.1f}] | - | "
        f"{human.duration_q10:.1f} / {human.duration_q50:.1f} / "
        f"{human.duration_q90:.1f} | {human.peak_q10:.2f} / {human.peak_q50:.2f} "
        f"/ {human.peak_q90:.2f} | n/a | n/a |",
    ]
    for name, m in results.items():
        s = statistics(m)
        coll = m["collisions"] / m["driven_hours"]
        lo, hi = poisson_rate_interval(m["lc_collisions"], m["driven_hours"])
        lcc = m["lc_collisions"] / m["driven_hours"]
        lines.append(
            f"| {name} | {s.rate:.1f} [{s.rate_low:.1f}, {s.rate_high:.1f}] | "
            f"{s.rate / human.rate - 1:+.0%} | {s.duration_q10:.1f} / "
            f"{s.duration_q50:.1f} / {s.duration_q90:.1f} | {s.peak_q10:.2f} / "
            f"{s.peak_q50:.2f} / {s.peak_q90:.2f} | {coll:.2f} | {lcc:.2f} "
            f"[{lo:.2f}, {hi:.2f}] |"
        )
    return "\n".join(lines)


def bundled(n: int, seed: int) -> str:
    """``highway_default`` against ``highway_lane_changes``: same draws of X, seeds."""
    from avrisk.assembly.builder import ScenarioSimulator, base_distribution
    from avrisk.rare.problem import chunk_rng, sample_seeds
    from avrisk.scenario import load_spec

    lines = [
        f"| scenario ({n} draws of X, seed {seed}) | environment vehicles ending in "
        "another lane | ego crash rate | P(f <= 0.3 s) | P(f <= 1 s) | f p10 [s] | "
        "rollouts whose f differs from highway_default's |",
        "|---|---|---|---|---|---|---|",
    ]
    reference = None
    for name in ("highway_default", "highway_lane_changes"):
        spec = load_spec(name)
        x = base_distribution(spec).sample(n, chunk_rng(seed, 0, 0))
        seeds = sample_seeds(seed, 0, np.arange(n))
        ss = ScenarioSimulator(spec)
        res = ss.rollout(x, seeds, record_trace=True)
        lanes = ss.road.lane_index(res.trace.y)[:, :, 1:]
        moved = float((lanes[:, -1] != lanes[:, 0]).float().mean())
        f = res.f.numpy()
        reference = f if reference is None else reference
        lines.append(
            f"| {name} | {moved:.3f} | {float(res.crash.float().mean()):.4f} | "
            f"{np.mean(f <= 0.3):.4f} | {np.mean(f <= 1.0):.4f} | "
            f"{np.percentile(f, 10):.2f} | {np.mean(f != reference):.4f} |"
        )
    return "\n".join(lines)


def main() -> None:
    """Calibrate (optionally), evaluate, print the tables, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=256)
    parser.add_argument("--horizon", type=float, default=60.0, help="[s]")
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--calibrate", action="store_true")
    parser.add_argument("--json", default=None, help="write the figures here")
    parser.add_argument(
        "--scenario-rollouts",
        type=int,
        default=2000,
        help="rollouts of highway_default and highway_lane_changes (0 skips)",
    )
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    t0 = time.perf_counter()
    net = load_driver_net()
    tables = load_lane_change_tables()
    train, held_out = (
        split_statistics(tables, "train"),
        split_statistics(tables, "test"),
    )
    noise = tables.noise_speed
    print(f"US-101 train: {fmt(train)}\nUS-101 held out: {fmt(held_out)}")
    params, log = LaneChangeParams(), None
    if args.calibrate:
        print("calibration scenes:")
        params, log = calibrate(
            net, Scenes(args.scenes, args.seed, args.horizon), train, noise
        )
    print(f"settings: {params}")
    results = evaluate(
        net, Scenes(args.scenes, args.seed + 1, args.horizon), params, noise
    )
    print()
    print(
        f"**Lane changes** ({args.scenes} random six-lane scenes x {N_VEHICLES} "
        f"vehicles x {args.horizon:g} s, seed {args.seed + 1}; learned drivers "
        "with xi ~ P0 per scene)"
    )
    print()
    print(table(held_out, results))
    if args.scenario_rollouts > 0:
        print()
        print(bundled(args.scenario_rollouts, args.seed + 2))
    print(
        f"\n_{time.perf_counter() - t0:.0f} s, torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads._"
    )
    if args.json:
        out = {
            "settings": dataclasses.asdict(params),
            "calibration": log,
            "us101_train": train.to_dict(),
            "us101_held_out": held_out.to_dict(),
            "evaluation": {
                name: {
                    **statistics(m).to_dict(),
                    "collisions": m["collisions"],
                    "lc_collisions": m["lc_collisions"],
                    "driven_hours": m["driven_hours"],
                }
                for name, m in results.items()
            },
        }
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
