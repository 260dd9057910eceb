"""Learned drivers in multi-lane traffic and in ``highway_idm``: parts B and C.

Part A of the realism check (car following on held-out NGSIM I-80 windows,
with issue 21's targets) and the lane changes against held-out US-101 vehicles
are ``avrisk realism`` (:mod:`avrisk.realism`). This script keeps the two
checks that need more than the package ships, with the same learned drivers
(``mu0``, ``xi ~ P0`` per rollout, mean actions; with the emergency brake their
weights carry) next to IDM+MOBIL:

B. Multi-lane traffic (6 lanes, 6 vehicles, random scenes unseen in
   training, 20 s): learned drivers for every vehicle vs IDM+MOBIL, with the
   human lane-change rate and speed/acceleration distributions of the US-101
   file as the human reference (raw NGSIM: accelerations are taken from the
   speed smoothed over 1 s, and jerk is not compared). The US-101 file does
   not ship with the package: set ``$AVRISK_NGSIM_DIR`` to a folder holding
   the original NGSIM files (``us101_vehicle_subset.csv.gz``; see
   :mod:`avrisk.learning.ngsim.loaders`).

C. The bundled scenario ``highway_idm`` with learned environment drivers
   (ego: IDM+MOBIL).

Usage::

    export AVRISK_NGSIM_DIR=/path/to/ngsim  # a folder of the original files
    .venv/bin/python benchmarks/driver_realism.py                  # shipped drivers
    .venv/bin/python benchmarks/driver_realism.py --drivers DIR --scenes 128
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from scipy.ndimage import uniform_filter1d

from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    load_driver_net,
    load_xi_prior,
)
from avrisk.agents.idm import IDMDriver
from avrisk.learning.imitation.simulated_demonstrations import random_highway_scenes
from avrisk.learning.ngsim.loaders import load_us101
from avrisk.learning.ngsim.samples import US101_LANE_WIDTH, episode_bounds
from avrisk.realism.car_following import learned_drivers
from avrisk.realism.lane_changes import frame_states
from avrisk.realism.metrics import (
    DT,
    HARD_BRAKE,
    hard_brake_events,
    kinematics,
    lane_index_changes,
    percentiles,
)
from avrisk.realism.tables import quantile_cell
from avrisk.safety import MinTTC
from avrisk.scenario import xi_base_family
from avrisk.sim import Road, SimConfig, Simulator
from avrisk.sim.collision import pairwise_overlap


def fmt_q(x: np.ndarray) -> str:
    return quantile_cell(percentiles(x))


# ------------------------------------------------------------------ part B
def us101_reference():
    us = load_us101()
    s, e = episode_bounds(us.vehicle_id)
    lcs, hours, speeds, accels = 0, 0.0, [], []
    for a, b in zip(s, e, strict=True):
        lat = uniform_filter1d(us.lateral[a:b], 10, mode="nearest") / US101_LANE_WIDTH
        lcs += lane_index_changes(lat[None, :], np.ones((1, b - a), bool))
        hours += (b - a) * DT / 3600
        # Raw NGSIM speeds are noisy: accelerations from a 1 s moving average.
        v = uniform_filter1d(us.speed[a:b], 10, mode="nearest")
        speeds.append(us.speed[a:b])
        accels.append(np.diff(v) / DT)
    acc = np.concatenate(accels)
    hard = (acc < HARD_BRAKE).astype(int)
    onsets = int(np.sum(np.diff(hard) == 1))
    return {
        "speed": np.concatenate(speeds),
        "accel": acc,
        "lc": lcs / hours,
        "hard": onsets / hours,
        "hours": hours,
    }


def part_b(net, fam, n_scenes: int, seed: int, horizon: float) -> str:
    road = Road()
    rng = np.random.default_rng(seed)
    a_veh = 6
    init, params = random_highway_scenes(n_scenes, a_veh, road, rng)
    drivers = learned_drivers(net, fam, n_scenes, rng, a_veh, net.guard)
    drivers["IDM+MOBIL"] = IDMDriver(params, road)
    human = us101_reference()
    sim = Simulator(road, SimConfig(horizon=horizon), measure=MinTTC(n_rays=1))
    results = {}
    for name, drv in drivers.items():
        res = sim.run(
            init, [drv], torch.arange(n_scenes, dtype=torch.int64), record_trace=True
        )
        tr = res.trace
        alive = tr.alive.numpy()[:, :, None].repeat(a_veh, 2)  # (B, T+1, A)
        v = tr.speed.numpy().transpose(0, 2, 1).reshape(-1, alive.shape[1])
        al = alive.transpose(0, 2, 1).reshape(-1, alive.shape[1])
        sv, sa, sj, a_full, ok = kinematics(v, al)
        hours = al[:, 1:].sum() * DT / 3600
        y = tr.y.numpy().transpose(0, 2, 1).reshape(-1, alive.shape[1])
        # Collisions between any two vehicles: onsets of overlap, per vehicle.
        onsets = 0
        off_onsets = 0
        prev = None
        prev_off = None
        for k, st in enumerate(frame_states(tr, init)):
            c, s_ = st.cos_sin
            now = pairwise_overlap(st, c, s_).any(-1) & tr.alive[:, k, None]
            half = 0.5 * (init.length * s_.abs() + init.width * c.abs())
            off = ((st.y - half < 0) | (st.y + half > road.width)) & tr.alive[
                :, k, None
            ]
            if prev is not None:
                onsets += int((now & ~prev).sum())
                off_onsets += int((off & ~prev_off).sum())
            prev, prev_off = now, off
        results[name] = {
            "speed": sv,
            "accel": sa,
            "jerk": sj,
            "lc": lane_index_changes(y / road.lane_width, al) / hours,
            "hard": hard_brake_events(a_full, ok) / hours,
            "crash": onsets / hours,
            "offroad": off_onsets / hours,
            "ego_crash": float(res.crash.float().mean()),
        }
    lines = [
        f"**B. Multi-lane traffic** ({n_scenes} random scenes x {a_veh} vehicles x "
        f"{horizon:.0f} s; human reference: US-101, {human['hours']:.1f} "
        "vehicle-hours, raw NGSIM)",
        "",
        "| metric | human (US-101) | " + " | ".join(results) + " |",
        "|---|---|" + "---|" * len(results),
        "| speed [m/s] p5/p50/p95 | "
        + fmt_q(human["speed"])
        + " | "
        + " | ".join(fmt_q(r["speed"]) for r in results.values())
        + " |",
        "| accel [m/s^2] p5/p50/p95 | "
        + fmt_q(human["accel"])
        + " | "
        + " | ".join(fmt_q(r["accel"]) for r in results.values())
        + " |",
        "| jerk [m/s^3] p5/p50/p95 | n/a (raw data) | "
        + " | ".join(fmt_q(r["jerk"]) for r in results.values())
        + " |",
        f"| lane changes [1/veh-h] | {human['lc']:.1f} | "
        + " | ".join(f"{r['lc']:.1f}" for r in results.values())
        + " |",
        f"| hard brakes (< -3 m/s^2) [1/veh-h] | {human['hard']:.1f} | "
        + " | ".join(f"{r['hard']:.1f}" for r in results.values())
        + " |",
        "| collisions (any pair, onsets) [1/veh-h] | n/a | "
        + " | ".join(f"{r['crash']:.1f}" for r in results.values())
        + " |",
        "| road departures (onsets) [1/veh-h] | n/a | "
        + " | ".join(f"{r['offroad']:.1f}" for r in results.values())
        + " |",
        "| rollouts whose vehicle 0 crashed [-] | n/a | "
        + " | ".join(f"{r['ego_crash']:.3f}" for r in results.values())
        + " |",
    ]
    return "\n".join(lines)


# ------------------------------------------------------------------ part C
def part_c(net, fam, n: int, seed: int) -> str:
    """The bundled scenario with learned environment drivers (ego: IDM+MOBIL)."""
    from avrisk.agents.idm import IDMPolicy
    from avrisk.assembly.builder import ScenarioSimulator
    from avrisk.assembly.parts import base_distribution, driver_params, initial_state
    from avrisk.scenario import load_spec
    from avrisk.scenario.params import ScenarioParams

    spec = load_spec("highway_idm")
    ss = ScenarioSimulator(spec)
    rng = np.random.default_rng(seed)
    x = base_distribution(spec).sample(n, rng)
    params = ScenarioParams.from_flat(x, ss.layout)
    state = initial_state(params, spec)
    idm = driver_params(spec, n)
    seeds = torch.arange(n, dtype=torch.int64)
    ego = IDMPolicy(idm, ss.road)
    drivers = learned_drivers(net, fam, n, rng, spec.n_vehicles, net.guard)
    rows = {}
    for name, drv in drivers.items():
        rows[name] = ss.simulator.run(state, [drv, ego], seeds)
    bundled = IDMDriver(idm, ss.road)
    rows["IDM+MOBIL (bundled)"] = ss.simulator.run(state, [bundled], seeds)
    lines = [
        f"**C. Bundled scenario `highway_idm`** ({n} draws of the initial "
        "conditions from P0; ego IDM+MOBIL; environment drivers as named)",
        "",
        "| environment drivers | ego crash rate | ego off-road rate | "
        "min TTC p1 / p10 / p50 [s] | P(f <= 0.3 s) |",
        "|---|---|---|---|---|",
    ]
    for name, res in rows.items():
        f = res.f.numpy()
        q = np.percentile(f, [1, 10, 50])
        lines.append(
            f"| {name} | {res.crash.float().mean():.4f} | "
            f"{res.offroad.float().mean():.4f} | "
            f"{q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f} | {np.mean(f <= 0.3):.4f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--drivers",
        type=Path,
        default=None,
        help="folder of driver_net.npz and xi_prior.npz (default: shipped)",
    )
    parser.add_argument(
        "--scenes", type=int, default=128, help="traffic scenes (part B)"
    )
    parser.add_argument(
        "--horizon", type=float, default=20.0, help="part B horizon [s]"
    )
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument(
        "--skip-b", action="store_true", help="skip part B (needs the US-101 file)"
    )
    parser.add_argument(
        "--scenario-rollouts",
        type=int,
        default=1000,
        help="part C rollouts of the bundled scenario (0 skips it)",
    )
    args = parser.parse_args()
    folder = args.drivers
    net = load_driver_net(folder / DRIVER_NET_FILE if folder else None)
    fam = xi_base_family(load_xi_prior(folder / XI_PRIOR_FILE if folder else None))
    t0 = time.perf_counter()
    if not args.skip_b:
        print(part_b(net, fam, args.scenes, args.seed + 1, args.horizon))
        print()
    if args.scenario_rollouts > 0:
        print(part_c(net, fam, args.scenario_rollouts, args.seed + 2))
        print()
    print(
        "_Command: `.venv/bin/python benchmarks/driver_realism.py "
        f"--scenes {args.scenes} --seed {args.seed}`; "
        f"{time.perf_counter() - t0:.0f} s, torch "
        f"{torch.__version__}, {torch.get_num_threads()} threads._"
    )


if __name__ == "__main__":
    main()
