"""Choose the learned drivers' emergency brake on training windows only.

Scores each ``--guards`` setting (``GAP,DECEL`` or ``GAP,DECEL,hold``;
``none`` for the network alone) by the crashes of each trained drivers'
folder on its closed-loop validation windows (training data:
:func:`avrisk.learning.training.selection.validation_crashes`, 8 replays per window,
leaders as recorded and with their speed changes made 1.5 times as large),
and prints one row per setting with the totals. The
held-out windows are not used: measure the chosen setting on them afterwards
with ``avrisk realism --drivers DIR --brake-guard GAP,DECEL``.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/brake_guard.py \\
        --drivers DIR:SEED [DIR:SEED ...] --guards none 1,2 2,1 2,2,hold

``SEED`` is the training's seed (``train-drivers --seed``): it fixes the
validation split. About 3 s per folder and setting on one thread.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from avrisk.agents.drivers.guard import parse_guard
from avrisk.agents.drivers.store import load_driver_net, load_xi_prior
from avrisk.learning.train_config import ClosedLoopConfig
from avrisk.learning.training.data import training_windows
from avrisk.learning.training.selection import validation_crashes

#: The settings scored when ``--guards`` is not given.
DEFAULT_GUARDS = ("none", "1,2", "1,1", "2,1", "2,0.5")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drivers", nargs="+", required=True, help="DIR:SEED")
    parser.add_argument(
        "--guards",
        nargs="+",
        type=parse_guard,
        default=[parse_guard(text) for text in DEFAULT_GUARDS],
        help="settings: none, GAP,DECEL or GAP,DECEL,hold (space-separated)",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = ClosedLoopConfig()
    windows = training_windows(None, config.window_steps)
    trainings = []
    for spec in args.drivers:
        folder, seed = spec.rsplit(":", 1)
        d = Path(folder)
        net = load_driver_net(d / "driver_net.npz")
        trainings.append((folder, int(seed), net, load_xi_prior(d / "xi_prior.npz")))
    rows = []
    print("| guard | " + " | ".join(f for f, *_ in trainings) + " | total |")
    print("|---|" + "---:|" * (len(trainings) + 1))
    for guard in args.guards:
        scores = [
            validation_crashes(net, prior, windows, config, seed, guard=guard)
            for _, seed, net, prior in trainings
        ]
        name = "none" if guard is None else guard.text()
        cells = [f"{s.stressed_crashes} / {s.crashes}" for s in scores]
        total = (
            sum(s.stressed_crashes for s in scores),
            sum(s.crashes for s in scores),
        )
        print(f"| {name} | " + " | ".join(cells) + f" | {total[0]} / {total[1]} |")
        rows.append(
            {"guard": name, "scores": [s.__dict__ for s in scores], "total": total}
        )
    print("cells: crashes with stressed leaders / as recorded, of", scores[0].replays)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
