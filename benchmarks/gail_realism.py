"""Does GAIL fine-tuning make the learned drivers more human? BC vs BC+GAIL.

Starts from the shipped behaviour-cloned (+ DAgger) network, fine-tunes its
acceleration head by GAIL with PPO (:func:`avrisk.learning.gail.gail_finetune`)
on the NGSIM I-80 *training* car-following windows, and compares both networks
on the *held-out* windows exactly as section A of ``driver_realism.py`` does
(15 s windows, leader replayed, same evaluation seed, ``mu0`` and ``xi ~ P0``;
the GAIL change of the head is carried over to the prior by
:func:`avrisk.learning.gail.translate_prior`). Nothing is tuned on the
held-out windows.

Usage::

    .venv/bin/python benchmarks/gail_realism.py                 # default config
    .venv/bin/python benchmarks/gail_realism.py --iterations 5  # quick look
    .venv/bin/python benchmarks/gail_realism.py --save /tmp/gail_net.npz
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from driver_realism import (  # noqa: E402
    DT,
    distances,
    hard_brake_events,
    held_out_windows,
    kinematics,
    ttc_samples,
)

from avrisk.agents.drivers.driver import LearnedDriver  # noqa: E402
from avrisk.agents.drivers.store import load_driver_net, load_xi_prior  # noqa: E402
from avrisk.learning.gail import GailConfig, gail_finetune, translate_prior  # noqa: E402
from avrisk.learning.replay import ReplayResult, replay  # noqa: E402
from avrisk.learning.training_data import training_windows  # noqa: E402
from avrisk.scenario import xi_base_family  # noqa: E402
from avrisk.sim import Road  # noqa: E402

KEYS = ("speed", "accel", "jerk", "gap", "ttc", "offset")


def samples(win, res) -> dict:
    """Distribution samples and event counts of one replay (or the human record)."""
    v, a, j, a_full, ok = kinematics(res.v, res.alive)
    lat = win.has_lateral
    return {
        "speed": v,
        "accel": a,
        "jerk": j,
        "gap": res.gap[res.alive],
        "ttc": ttc_samples(res.gap, res.v, res.v_l, res.alive),
        "offset": res.offset[lat][res.alive[lat]],
        "hard": hard_brake_events(a_full, ok),
        "crash": int(res.crash.sum()),
        "offroad": int(res.offroad.sum()),
    }


def human_samples(win) -> dict:
    none = np.zeros(len(win), bool)
    record = ReplayResult(
        v=win.v_f,
        v_l=win.v_l,
        gap=win.gap,
        offset=win.offset,
        alive=np.ones_like(win.v_f, bool),
        crash=none,
        offroad=none,
    )
    return samples(win, record)


def drivers(bc, gail, fam_bc, fam_gail, n: int, seed: int) -> dict:
    """BC and BC+GAIL at mu0 and with the same standard draws of xi ~ P0."""
    out = {}
    both = torch.ones(2, dtype=torch.bool)  # follower and leader of a replay
    for tag, net, fam in (("BC", bc, fam_bc), ("BC+GAIL", gail, fam_gail)):
        xi = torch.as_tensor(
            fam.sample(n, np.random.default_rng(seed)), dtype=torch.float32
        )
        mu0 = torch.as_tensor(fam.mean).float()
        out[f"{tag} mu0"] = LearnedDriver(net, mu0, controlled=both)
        out[f"{tag} xi~P0"] = LearnedDriver(net, xi, controlled=both)
    return out


def table(win, results: dict, human: dict, hours: float) -> str:
    names = list(results)
    lines = [
        "| metric | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for key in KEYS:
        cells = [distances(r[key], human[key]) for r in results.values()]
        lines.append(f"| {key} KS / W1 | " + " | ".join(cells) + " |")
    for key, label in (
        ("hard", f"hard brakes [1/veh-h] (human {human['hard'] / hours:.1f})"),
        ("crash", "collisions [1/veh-h] (human 0)"),
        ("offroad", "road departures [1/veh-h] (human 0)"),
    ):
        cells = [f"{r[key] / hours:.1f}" for r in results.values()]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    cells = [f"{r['crash']} / {len(win)}" for r in results.values()]
    lines.append("| windows ending in a collision | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--iterations", type=int, default=GailConfig().iterations)
    parser.add_argument("--gail-seed", type=int, default=0)
    parser.add_argument("--seed", type=int, default=2024, help="evaluation seed")
    parser.add_argument("--window", type=float, default=15.0, help="window length [s]")
    parser.add_argument("--save", default=None, help="write the tuned driver_net.npz")
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    n_steps = round(args.window / DT)
    road = Road()
    bc = load_driver_net()
    prior = load_xi_prior()
    t0 = time.perf_counter()
    gail, history = gail_finetune(
        bc,
        training_windows(None, n_steps),
        GailConfig(iterations=args.iterations),
        args.gail_seed,
        road=road,
    )
    t_train = time.perf_counter() - t0
    if args.save:
        gail.save(args.save)
    fam_bc = xi_base_family(prior)
    fam_gail = xi_base_family(translate_prior(prior, bc, gail))
    win = held_out_windows(n_steps, road)
    hours = len(win) * n_steps * DT / 3600
    models = drivers(bc, gail, fam_bc, fam_gail, len(win), args.seed)
    results = {
        name: samples(win, replay(win, drv, road, seed=args.seed))
        for name, drv in models.items()
    }
    first, last = history[0], history[-1]
    print(
        f"**BC vs BC+GAIL, car following on held-out NGSIM I-80** ({len(win)} "
        f"windows of {args.window:.0f} s, {hours:.2f} vehicle-hours; KS / W1 vs "
        "the human followers)\n"
    )
    print(table(win, results, human_samples(win), hours))
    print(
        f"\nGAIL training ({args.iterations} iterations, {t_train:.0f} s): "
        f"discriminator accuracy {first['disc_accuracy']:.3f} -> "
        f"{last['disc_accuracy']:.3f}, GAIL reward per step "
        f"{first['mean_reward']:.3f} -> {last['mean_reward']:.3f}, entropy "
        f"{first['entropy']:.2f} -> {last['entropy']:.2f} nats, training-window "
        f"collision rate {first['collision_rate']:.3f} -> "
        f"{last['collision_rate']:.3f}."
    )
    print(
        "\n_Command: `.venv/bin/python benchmarks/gail_realism.py --iterations "
        f"{args.iterations} --gail-seed {args.gail_seed} --seed {args.seed}`; "
        f"{time.perf_counter() - t0:.0f} s, torch {torch.__version__}, "
        f"{torch.get_num_threads()} thread._"
    )


if __name__ == "__main__":
    main()
