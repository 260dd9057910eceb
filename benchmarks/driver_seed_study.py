"""Leave one I-80 period out, over training seeds: the seed study of issue 44.

Trains the driver recipe once per (fold, seed, recipe), one training at a
time, validates each on its own period's test split (below) and scores it on
the period it did not see (:func:`avrisk.realism.report.run_realism` with
``held_out`` set to that period), with the brake its weights carry, with the
brake fitted to the fold's training windows (:mod:`avrisk.learning.guard_fit`)
and with the network alone. Each result is written as it finishes to
``RESULTS/{fold}_{recipe}_seed{S}.json`` (the realism summary: every target and
margin, overall and by speed band). Resumable: a result that exists is
skipped, a training whose folder holds its files is not trained again, and a
training left without its results (the scoring failed) is validated and scored
again before the next training starts::

    nohup nice -n 19 env OMP_NUM_THREADS=1 .venv/bin/python \\
        benchmarks/driver_seed_study.py run --folds A B --seeds 0-5 &

Folds (:data:`FOLDS`): ``A`` trains on 16:00-16:15 (both I-80 files) and is
scored on 17:00-17:15; ``B`` trains on 17:00-17:15 (the car-following pairs
only: the lateral file covers 16:00-16:15) and is scored on 16:00-16:15 (its
pairs and its lateral windows); ``all`` trains on both and is scored on the
test splits (the default ``avrisk realism`` set), which it did not train on.
A recipe is chosen on the training period's own test split, which no
training reads (``validate FOLD RECIPE SEED``: ``avrisk realism --held-out
PERIOD:test``, written to ``..._validation.json``), before its score on the
other period. Every training, validation and scoring runs in its own process
(``train``, ``validate`` and ``score`` sub-commands), with the CPU kernels
pinned as for the shipped files
(:data:`~avrisk.learning.training.report.KERNEL_PINS`).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: Trained drivers, one folder per (fold, recipe, seed); not committed.
RUNS = ROOT / "runs" / "driver_seeds"
#: One JSON per (fold, recipe, seed).
RESULTS = ROOT / "benchmarks" / "results" / "driver_seeds"

#: fold: (periods trained on, held-out set scored).
FOLDS = {
    "A": (("0400pm-0415pm",), "0500pm-0515pm"),
    "B": (("0500pm-0515pm",), "0400pm-0415pm"),
    "all": (None, "test"),
}


def recipe_config(name: str, periods: tuple[str, ...] | None) -> Any:
    """The :class:`~avrisk.learning.train_config.TrainConfig` of recipe ``name``.

    ``shipped``: the defaults that made the shipped files. ``balanced``: the
    closed loop's minibatches drawn half from congested windows
    (``ClosedLoopConfig.congested_share = 0.5``). ``fitted_brake``: the brake
    fitted to the fold's training windows
    (:func:`~avrisk.learning.guard_fit.fit_brake_guard`), trained with as the
    shipped recipe trains with its brake. Each is a rule on the training
    windows alone. ``network_alone``: the shipped recipe with every closed-loop
    replay driven by the network alone (``ClosedLoopConfig.drive_with_guard =
    False``; the weights still carry the shipped brake), so that the network
    meets the outcome of its own closing in ordinary traffic too, not only in
    the stress replays. ``idm_head``: the shipped recipe with the IDM's
    car-following law in the network (``TrainConfig.head = "idm"``,
    :mod:`avrisk.agents.drivers.idm_head`): the network sets the gap a driver
    keeps, the IDM the acceleration that keeps it, so a period's closing
    behaviour is a matter of gaps the network learns, not of an acceleration
    law it must extrapolate to traffic it never saw. ``idm_head_imitation``:
    the IDM head with the closed loop's adversarial term off
    (``ClosedLoopConfig.adversarial_weight = 0``), so that its steps descend
    the imitation loss (speed and gap along each replay) and the barriers
    alone, the loss its early stopping already selects on.
    ``idm_head_imitation5``: the IDM head with the imitation term five times
    as heavy (``ClosedLoopConfig.imitation_weight = 5``) beside the
    adversarial one.
    """
    from avrisk.learning.guard_fit import fit_brake_guard
    from avrisk.learning.train_config import TrainConfig
    from avrisk.learning.training.data import training_windows

    default = TrainConfig()
    if name == "shipped":
        config = default
    elif name == "balanced":
        balanced = replace(default.closed_loop, congested_share=0.5)
        config = replace(default, closed_loop=balanced)
    elif name == "fitted_brake":
        windows = training_windows(None, default.closed_loop.window_steps, periods)
        config = replace(default, guard=fit_brake_guard(windows).guard)
    elif name == "network_alone":
        alone = replace(default.closed_loop, drive_with_guard=False)
        config = replace(default, closed_loop=alone)
    elif name == "idm_head":
        config = replace(default, head="idm")
    elif name == "idm_head_imitation":
        imitation = replace(default.closed_loop, adversarial_weight=0.0)
        config = replace(default, head="idm", closed_loop=imitation)
    elif name == "idm_head_imitation5":
        heavier = replace(default.closed_loop, imitation_weight=5.0)
        config = replace(default, head="idm", closed_loop=heavier)
    else:
        raise SystemExit(
            f"unknown recipe {name!r}: shipped, balanced, fitted_brake, "
            "network_alone, idm_head, idm_head_imitation, idm_head_imitation5"
        )
    return replace(config, periods=periods)


def _folder(fold: str, recipe: str, seed: int) -> Path:
    return RUNS / f"{fold}_{recipe}" / f"seed-{seed}"


def _result(fold: str, recipe: str, seed: int) -> Path:
    return RESULTS / f"{fold}_{recipe}_seed{seed}.json"


def train(fold: str, recipe: str, seed: int) -> None:
    """One training into its folder."""
    import torch

    from avrisk.learning.training.train import train_drivers

    torch.set_num_threads(1)
    periods, _ = FOLDS[fold]
    out = _folder(fold, recipe, seed)
    t0 = time.perf_counter()
    train_drivers(seed, out, config=recipe_config(recipe, periods), threads=1)
    print(f"trained {out} in {time.perf_counter() - t0:.0f} s", flush=True)


def score(fold: str, recipe: str, seed: int) -> None:
    """Score one training on its fold's held-out set; write its JSON.

    Three brakes: the one the weights carry (trained with), the one fitted
    to the fold's training windows (:func:`~avrisk.learning.guard_fit.
    fit_brake_guard`), and none (the network alone; where the carried brake
    would have acted is still counted).
    """
    import torch

    from avrisk.agents.drivers.store import load_driver_net
    from avrisk.learning.guard_fit import fit_brake_guard
    from avrisk.learning.training.data import training_windows
    from avrisk.realism.periods import score_summary
    from avrisk.realism.report import DriverFiles, RealismSettings, run_realism

    torch.set_num_threads(1)
    periods, held_out = FOLDS[fold]
    folder = _folder(fold, recipe, seed)
    report = json.loads((folder / "training_report.json").read_text())
    own = load_driver_net(folder / "driver_net.npz").guard
    fit = fit_brake_guard(training_windows(None, 150, periods))
    t0 = time.perf_counter()
    scored = {}
    for key, brake in (
        ("with_brake", own),
        ("fitted_brake", fit.guard),
        ("network_alone", None),
    ):
        settings = RealismSettings(held_out=held_out, guard=brake)
        result = run_realism(DriverFiles.in_folder(folder), settings)
        scored[key] = score_summary(result, brake or own)
    out = {
        "fold": fold,
        "recipe": recipe,
        "seed": seed,
        "trained_on": periods or "all periods (train splits)",
        "held_out": held_out,
        "brake_fit": fit.to_dict(),
        "training_seconds": report["seconds"],
        "config": report["config"],
        "environment": report["environment"],
        "scoring_seconds": round(time.perf_counter() - t0, 1),
        **scored,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    _result(fold, recipe, seed).write_text(json.dumps(out, indent=1) + "\n")
    print(f"scored {folder}", flush=True)


def validate(fold: str, recipe: str, seed: int) -> None:
    """Score one training on its own period's test split (in fold); write its JSON.

    The set a recipe is chosen on before its score on the period it never
    saw: ``held_out = "{period}:test"``, which no training reads. With the
    brake the weights carry and with the network alone.
    """
    import torch

    from avrisk.agents.drivers.store import load_driver_net
    from avrisk.realism.periods import score_summary
    from avrisk.realism.report import DriverFiles, RealismSettings, run_realism

    torch.set_num_threads(1)
    held_out = _validation_set(fold)
    if held_out is None:
        raise SystemExit(f"fold {fold} trains on no single period to validate on")
    folder = _folder(fold, recipe, seed)
    own = load_driver_net(folder / "driver_net.npz").guard
    out: dict[str, Any] = {"fold": fold, "recipe": recipe, "seed": seed}
    out["validated_on"] = held_out
    for key, brake in (("with_brake", own), ("network_alone", None)):
        settings = RealismSettings(held_out=held_out, guard=brake)
        result = run_realism(DriverFiles.in_folder(folder), settings)
        out[key] = score_summary(result, brake or own)
    RESULTS.mkdir(parents=True, exist_ok=True)
    _validation(fold, recipe, seed).write_text(json.dumps(out, indent=1) + "\n")
    print(f"validated {folder}", flush=True)


def _child(*args: str) -> bool:
    """Run this script's sub-command in a fresh process; True if it succeeded."""
    from avrisk.learning.training.report import KERNEL_PINS

    env = {**os.environ, **KERNEL_PINS, "OMP_NUM_THREADS": "1"}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, __file__, *args], env=env, check=False)
    return done.returncode == 0


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def run(folds: list[str], seeds: list[int], recipes: list[str]) -> None:
    """Every (recipe, seed, fold) in turn, validated in fold and scored; resumable."""
    jobs = [(f, r, s) for r in recipes for s in seeds for f in folds]
    for fold, recipe, seed in jobs:
        _score_pending(jobs)
        if not (_folder(fold, recipe, seed) / "training_report.json").exists():
            print(f"training {fold} {recipe} seed {seed}", flush=True)
            if not _child("train", fold, recipe, str(seed)):
                continue
        _score_pending([(fold, recipe, seed)])
    _score_pending(jobs)


def _validation_set(fold: str) -> str | None:
    """``"{period}:test"`` of a fold trained on one period; None otherwise."""
    periods, _ = FOLDS[fold]
    return f"{periods[0]}:test" if periods is not None and len(periods) == 1 else None


def _validation(fold: str, recipe: str, seed: int) -> Path:
    return RESULTS / f"{fold}_{recipe}_seed{seed}_validation.json"


def _score_pending(jobs: list[tuple[str, str, int]]) -> None:
    """Validate and score every trained job whose results are missing."""
    for fold, recipe, seed in jobs:
        if not (_folder(fold, recipe, seed) / "training_report.json").exists():
            continue
        in_fold = _validation_set(fold) is not None
        if in_fold and not _validation(fold, recipe, seed).exists():
            _child("validate", fold, recipe, str(seed))
        if not _result(fold, recipe, seed).exists():
            _child("score", fold, recipe, str(seed))


#: The learned model the tables show.
MODEL = "learned xi~P0"


def _target_cell(t: dict[str, Any], digits: int = 2) -> str:
    mark = "" if t["passed"] else " **x**"
    return f"{t['value']:.{digits}f} ({t['margin']:+.2f}){mark}"


def _results(validation: bool) -> list[dict[str, Any]]:
    """The left-out scores, or the in-fold ones (``validate``'s)."""
    return [
        json.loads(p.read_text())
        for p in sorted(RESULTS.glob("*.json"))
        if p.stem.endswith("_validation") == validation
    ]


def _target_cells(own: dict[str, Any]) -> str:
    """The targets' cells of one set, from accel p5 to all targets."""
    t = own["targets"][MODEL]
    human = own["human"]["p5"]
    ks = t["TTC KS below IDM's"]
    ks_idm = own["models"]["IDM"]["ks"]["ttc"]
    return (
        f"{_target_cell(t['accel p5 within 15%'])} [h {human['accel']:.2f}] | "
        f"{_target_cell(t['gap p5 within 10%'])} [h {human['gap']:.2f}] | "
        f"{_target_cell(t['TTC p5 within 10%'])} [h {human['ttc']:.2f}] | "
        f"{_target_cell(t['time stopped within 25%'], 3)} | "
        f"{t['closer to humans than IDM (8 of the 9 metrics)']['value']:.0f} "
        f"of 8 | {ks['value']:.3f} ({ks_idm:.3f}) | "
        f"{'pass' if own['all_passed'][MODEL] else 'FAIL'}"
    )


#: The targets' columns of both tables.
TARGET_HEAD = (
    "accel p5 | gap p5 [m] | TTC p5 [s] | time stopped | closer than IDM | "
    "TTC KS (IDM) | all targets"
)


def table() -> str:
    """Markdown tables of every left-out score in :data:`RESULTS` (``xi ~ P0``)."""
    head = (
        "| fold / recipe / seed | set (median speed) | collisions /veh-h: own "
        f"brake / fitted / none | {TARGET_HEAD} | own brake acts /veh-h: "
        "drivers / humans |"
    )
    lines = [head, "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in _results(validation=False):
        for band in ("all", "congested", "flowing"):
            own = r["with_brake"][band]
            coll = [
                r[k][band]["models"][MODEL]["collisions_per_hour"]
                for k in ("with_brake", "fitted_brake", "network_alone")
            ]
            use = own.get("brake_use", {})
            acts = (
                f"{use[MODEL]['onsets']['per_hour']:.0f} / "
                f"{use['human']['onsets']['per_hour']:.0f}"
                if use
                else "-"
            )
            lines.append(
                f"| {r['fold']} / {r['recipe']} / {r['seed']} | {r['held_out']} "
                f"{band} ({own['windows']} windows, {own['human_median_speed']:.1f} "
                f"m/s) | {' / '.join(f'{c:.2f}' for c in coll)} | "
                f"{_target_cells(own)} | {acts} |"
            )
    return "\n".join(lines)


def validation_table() -> str:
    """A markdown table of every in-fold score (``validate``; all windows)."""
    head = (
        "| fold / recipe / seed | set (median speed) | collisions /veh-h: own "
        f"brake / none | speed KS (IDM) | accel KS (IDM) | {TARGET_HEAD} |"
    )
    lines = [head, "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in _results(validation=True):
        own = r["with_brake"]["all"]
        coll = [
            r[k]["all"]["models"][MODEL]["collisions_per_hour"]
            for k in ("with_brake", "network_alone")
        ]
        speed, accel = (
            f"{own['models'][MODEL]['ks'][k]:.3f} ({own['models']['IDM']['ks'][k]:.3f})"
            for k in ("speed", "accel")
        )
        lines.append(
            f"| {r['fold']} / {r['recipe']} / {r['seed']} | {r['validated_on']} "
            f"({own['windows']} windows, {own['human_median_speed']:.1f} m/s) | "
            f"{' / '.join(f'{c:.2f}' for c in coll)} | {speed} | {accel} | "
            f"{_target_cells(own)} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="train and score every job (resumable)")
    p_run.add_argument("--folds", nargs="+", default=["A", "B"], choices=FOLDS)
    p_run.add_argument("--seeds", default="0-5", help="e.g. 0-5")
    p_run.add_argument("--recipes", nargs="+", default=["shipped"])
    p_table = sub.add_parser("table", help="print the results as a markdown table")
    p_table.add_argument(
        "--validation", action="store_true", help="the in-fold scores (validate's)"
    )
    for name in ("train", "score", "validate"):
        p = sub.add_parser(name)
        p.add_argument("fold", choices=FOLDS)
        p.add_argument("recipe")
        p.add_argument("seed", type=int)
    args = parser.parse_args()
    if args.command == "run":
        run(args.folds, _seeds(args.seeds), args.recipes)
    elif args.command == "table":
        print(validation_table() if args.validation else table())
    elif args.command == "train":
        train(args.fold, args.recipe, args.seed)
    elif args.command == "validate":
        validate(args.fold, args.recipe, args.seed)
    else:
        score(args.fold, args.recipe, args.seed)


if __name__ == "__main__":
    main()
