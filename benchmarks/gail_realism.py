"""Does GAIL fine-tuning make the learned drivers more human? BC vs BC+GAIL.

Starts from the shipped behaviour-cloned (+ DAgger) network, fine-tunes its
acceleration head by GAIL with PPO (:func:`gail_ppo.gail_finetune`, in the
module beside this file) on the NGSIM I-80 *training* car-following windows,
and compares both networks on the *held-out* windows exactly as part A of
``avrisk realism`` does (15 s windows, leader replayed, same evaluation seed,
``mu0`` and ``xi ~ P0``; the GAIL change of the head is carried over to the
prior by :func:`gail_ppo.translate_prior`). Nothing is tuned on the held-out
windows.

Usage::

    .venv/bin/python benchmarks/gail_realism.py                 # default config
    .venv/bin/python benchmarks/gail_realism.py --iterations 5  # quick look
    .venv/bin/python benchmarks/gail_realism.py --save /tmp/gail_net.npz
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

# benchmarks/, this script's folder, is first on sys.path when it runs.
from gail_ppo import GailConfig, gail_finetune, translate_prior

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
from avrisk.learning.replay import replay
from avrisk.learning.training.data import training_windows
from avrisk.realism.car_following import QUANTITIES, Followers, followers, recorded
from avrisk.realism.held_out import held_out_windows
from avrisk.realism.metrics import DT, ks_w1
from avrisk.scenario import xi_base_family
from avrisk.sim import Road


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


def distance(f: Followers, human: Followers, key: str) -> str:
    d = ks_w1(f.samples[key], human.samples[key])
    return "n/a" if d is None else f"{d[0]:.3f} / {d[1]:.3g}"


def table(win, results: dict[str, Followers], human: Followers) -> str:
    names = list(results)
    lines = [
        "| metric | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for key in QUANTITIES:
        cells = [distance(r, human, key) for r in results.values()]
        lines.append(f"| {key} KS / W1 | " + " | ".join(cells) + " |")
    for key, label in (
        (
            "hard_brakes",
            f"hard brakes [1/veh-h] (human {human.hard_brakes / human.hours:.1f})",
        ),
        ("collisions", "collisions [1/veh-h] (human 0)"),
        ("road_departures", "road departures [1/veh-h] (human 0)"),
    ):
        cells = [f"{getattr(r, key) / r.hours:.1f}" for r in results.values()]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    cells = [f"{r.collisions} / {len(win)}" for r in results.values()]
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
    labels = np.arange(len(win))
    models = drivers(bc, gail, fam_bc, fam_gail, len(win), args.seed)
    results = {
        name: followers(win, replay(win, drv, road, seed=args.seed), road, labels)
        for name, drv in models.items()
    }
    first, last = history[0], history[-1]
    print(
        f"**BC vs BC+GAIL, car following on held-out NGSIM I-80** ({len(win)} "
        f"windows of {args.window:.0f} s, {hours:.2f} vehicle-hours; KS / W1 vs "
        "the human followers)\n"
    )
    print(table(win, results, followers(win, recorded(win), road, labels)))
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
