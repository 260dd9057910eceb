"""Training the learned drivers and ``P0(xi)`` from data: the stages in order.

Pipeline of :func:`train_drivers`, one module of :mod:`avrisk.learning` a
stage::

    demonstrations  = NGSIM I-80 pairs (train split)           longitudinal
                    + NGSIM I-80 lateral pairs (train split)    + lane keeping
                    + IDM+MOBIL in our simulator                neighbours
                                                    (training/data.py)
    trunk + head    = argmin weighted Gaussian NLL  (Adam)      behaviour cloning
                                                    (imitation/behaviour_cloning.py)
    sampling noise  = AR(1) from human residuals, scale by replays
                                                    (training/sampling_noise.py)
    DAgger x K      = learner drives, IDM+MOBIL labels the       covariate shift
                      visited states; refit on the aggregate
                                                    (imitation/dagger.py)
    sampling noise  = again, for the final network
    closed loop     = back-propagation through replays of       closed-loop
                      training windows: imitation + MGAIL        realism
                      reward + gap and TTC barriers, and
                      hard-braking windows with their leaders
                      braking harder, under the barriers
                                                    (training/closed_loop.py,
                                                     imitation/mgail.py)
    heads 1..m      = the head refitted on m bootstrap resamples of the
                      episodes (trunk frozen, so the heads are comparable),
                      then moved together so that their mean is the
                      closed-loop head              (prior/bootstrap_heads.py)
    mu0, Sigma0^-1  = ensemble mean, Ledoit-Wolf + graphical lasso
                                                    (prior/xi_prior_fit.py)
    files, report   = driver_net.npz (with the emergency brake
                      TrainConfig.guard, which training itself never
                      drives with), xi_prior.npz, training_report.json
                                                    (training/report.py)

The settings of every stage are one
:class:`~avrisk.learning.train_config.TrainConfig`. With ``candidates > 1``
the recipe is trained with as many seeds and the training whose drivers (with
their emergency brake) crash least on their own closed-loop validation
windows is kept (:mod:`avrisk.learning.training.selection`; training data
only): trainings of one recipe differ widely in how often their drivers
crash.
The shipped files are ``driver_net.npz`` (trunk + shared head) and
``xi_prior.npz`` (``mu0``, sparse precision, members); see
:mod:`avrisk.agents.drivers.store`. The run is seeded: the same seed, data
and machine give the same files (torch's CPU kernels are deterministic for a
fixed thread count).

The paper trains its generators with model-based GAIL (a discriminator's
reward back-propagated through a model); the closed-loop stage here
back-propagates that reward, an imitation loss of the recorded trajectories
and gap and TTC barriers through the simulator itself (BENCHMARKS.md compares
it with each part alone and with GAIL).
"""

from __future__ import annotations

import json
import multiprocessing
import shutil
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    load_driver_net,
    load_xi_prior,
)
from avrisk.learning.imitation.behaviour_cloning import fit_driver_net
from avrisk.learning.imitation.dagger import dagger_rounds
from avrisk.learning.imitation.demonstrations import Demonstrations
from avrisk.learning.prior.bootstrap_heads import bootstrap_heads, centre_heads
from avrisk.learning.prior.xi_prior_fit import fit_xi_prior, validation_nll
from avrisk.learning.train_config import Progress, TrainConfig, TrainEvent
from avrisk.learning.training.closed_loop import closed_loop_finetune
from avrisk.learning.training.data import load_demonstrations, training_windows
from avrisk.learning.training.report import (
    TRAINING_REPORT_FILE,
    TrainingReport,
    training_environment,
    write_training_outputs,
)
from avrisk.learning.training.sampling_noise import fit_sampling_noise
from avrisk.learning.training.selection import (
    REPLICATES,
    STRESS,
    CandidateScore,
    choose,
    validation_crashes,
)

__all__ = ["CANDIDATES_DIR", "train_drivers"]

#: Sub-folder of ``out_dir`` for the trainings among which ``candidates``
#: chooses, one ``seed-S`` folder each.
CANDIDATES_DIR = "candidates"


def train_drivers(
    seed: int = 0,
    out_dir: str | Path = "drivers",
    *,
    data_dir: str | Path | None = None,
    config: TrainConfig | None = None,
    progress: Progress | None = None,
    threads: int | None = 1,
    candidates: int = 1,
    workers: int = 1,
) -> TrainingReport:
    """Reproduce the shipped driver network and ``xi`` distribution from data.

    Parameters
    ----------
    seed : int, default=0
        Seeds everything (network init, shuffling, bootstrap, simulated scenes).
    out_dir : str or Path, default="drivers"
        Receives ``driver_net.npz``, ``xi_prior.npz`` and
        ``training_report.json`` (created if missing).
    data_dir : str or Path, optional
        NGSIM folder; default ``$AVRISK_NGSIM_DIR``, else the data shipped
        with the package (:func:`avrisk.learning.ngsim.files.ngsim_dir`).
    config : TrainConfig, optional
        Default ``TrainConfig()``, the settings of the shipped files.
    progress : callable, optional
        Receives :class:`~avrisk.learning.train_config.TrainEvent` reports
        (for a progress bar).
    threads : int or None, default=1
        torch CPU threads during the run (restored afterwards). With one
        thread the run is bit-reproducible on a machine; a multi-threaded BLAS
        may split reductions differently from run to run. None keeps the
        current setting.
    candidates : int, default=1
        Trainings of the recipe, with seeds ``seed, seed + 1, ...``. With
        more than one, each is written to ``out_dir/candidates/seed-S/`` and
        scored by its drivers' crashes on its own closed-loop validation
        windows (:func:`~avrisk.learning.training.selection.validation_crashes`), and
        the one with the fewest is copied to ``out_dir``; its report's
        ``selection`` lists every candidate's score. A candidate's files are
        those of ``train_drivers(seed + k)``.
    workers : int, default=1
        With several candidates, train them in this many processes at once
        (one thread each; the same files as one after the other).

    Returns
    -------
    TrainingReport
        Of the training written to ``out_dir`` (the chosen one).

    Raises
    ------
    ValueError
        For ``candidates < 1`` or ``workers < 1``.
    """
    if candidates < 1 or workers < 1:
        raise ValueError(
            f"candidates and workers must be >= 1; got {candidates} and {workers}"
        )
    config = TrainConfig() if config is None else config
    previous = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        if candidates == 1:
            return _train_drivers(seed, Path(out_dir), data_dir, config, progress)
        return _train_candidates(
            seed, candidates, Path(out_dir), data_dir, config, progress, workers
        )
    finally:
        torch.set_num_threads(previous)


def _train_candidates(
    seed: int,
    candidates: int,
    out: Path,
    data_dir: str | Path | None,
    config: TrainConfig,
    progress: Progress | None,
    workers: int,
) -> TrainingReport:
    """Train seeds ``seed .. seed + candidates - 1``; keep the fewest crashes."""
    seeds = [seed + k for k in range(candidates)]
    folders = [out / CANDIDATES_DIR / f"seed-{s}" for s in seeds]
    results: dict[int, tuple[TrainingReport, CandidateScore]] = {}

    def done(s: int, result: tuple[TrainingReport, CandidateScore]) -> None:
        results[s] = result
        if progress is not None:
            metrics = {"stressed_crashes": float(result[1].stressed_crashes)}
            progress(TrainEvent("candidates", len(results), candidates, metrics))

    if workers == 1:
        for s, folder in zip(seeds, folders, strict=True):
            done(s, _train_and_score(s, folder, data_dir, config, progress, None))
    else:
        # One single-threaded process per candidate: the same files as in
        # this process (spawned, so that no torch state is inherited).
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(workers, candidates), mp_context=context) as pool:
            futures = {
                pool.submit(_train_and_score, s, f, data_dir, config, None, 1): s
                for s, f in zip(seeds, folders, strict=True)
            }
            for future in as_completed(futures):
                done(futures[future], future.result())
    scores = [results[s][1] for s in seeds]
    best = choose(scores)
    chosen = out / CANDIDATES_DIR / f"seed-{best.seed}"
    for name in (DRIVER_NET_FILE, XI_PRIOR_FILE):
        shutil.copyfile(chosen / name, out / name)
    selection = {
        "criterion": (
            f"fewest crashes in {REPLICATES} replays of every closed-loop "
            f"validation window, xi ~ P0, leaders' speed changes x{STRESS}; "
            "then crashes with the recorded leaders; then the lowest seed"
        ),
        "chosen_seed": best.seed,
        "candidates": [asdict(score) for score in scores],
    }
    report = replace(results[best.seed][0], out_dir=str(out), selection=selection)
    (out / TRAINING_REPORT_FILE).write_text(json.dumps(report.to_dict(), indent=2))
    return report


def _train_and_score(
    seed: int,
    folder: Path,
    data_dir: str | Path | None,
    config: TrainConfig,
    progress: Progress | None,
    threads: int | None,
) -> tuple[TrainingReport, CandidateScore]:
    """One candidate: its training in ``folder``, then its validation crashes."""
    if threads is not None:
        torch.set_num_threads(threads)
    report = _train_drivers(seed, folder, data_dir, config, progress)
    windows = training_windows(
        data_dir, config.closed_loop.window_steps, config.periods
    )
    net = load_driver_net(folder / DRIVER_NET_FILE)
    prior = load_xi_prior(folder / XI_PRIOR_FILE)
    score = validation_crashes(
        net, prior, windows, config.closed_loop, seed, guard=net.guard
    )
    return report, score


class _Stopwatch:
    """Wall time of consecutive stages [s], rounded to 0.01 s."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._start = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Record the time since the previous lap as ``stage``'s."""
        now = time.perf_counter()
        self.seconds[stage] = round(now - self._start, 2)
        self._start = now


def _closed_loop_stage(
    net: DriverNet,
    data_dir: str | Path | None,
    config: TrainConfig,
    seed: int,
    progress: Progress | None,
) -> list[dict[str, float]]:
    """The closed-loop stage on the training windows (its history; [] if off)."""
    if config.closed_loop.iterations == 0:
        return []
    return closed_loop_finetune(
        net,
        training_windows(data_dir, config.closed_loop.window_steps, config.periods),
        config.closed_loop,
        seed,
        progress,
        guard=config.guard if config.closed_loop.drive_with_guard else None,
    )


def _ensemble_stage(
    net: DriverNet,
    train: Demonstrations,
    config: TrainConfig,
    seed: int,
    progress: Progress | None,
) -> tuple[NDArray[np.float64], list[dict[str, float]]]:
    """The bootstrap heads, centred on the network's head, and their history."""
    heads, history = bootstrap_heads(
        net,
        train,
        config.n_members,
        epochs=config.head_epochs,
        batch_size=config.head_batch_size,
        lr=config.head_lr,
        seed=seed,
        progress=progress,
    )
    return centre_heads(heads, net), history


def _train_drivers(
    seed: int,
    out: Path,
    data_dir: str | Path | None,
    config: TrainConfig,
    progress: Progress | None,
) -> TrainingReport:
    stopwatch = _Stopwatch()
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    train, val, data_meta = load_demonstrations(data_dir, seed, config)
    if progress is not None:
        progress(
            TrainEvent("data", 1, 1, {"train_rows": len(train), "val_rows": len(val)})
        )
    stopwatch.lap("data")

    net, trunk_history = fit_driver_net(train, val, config, seed, progress)
    stopwatch.lap("trunk")

    windows = None
    if config.calibration_windows > 0:
        windows = training_windows(
            data_dir, config.calibration_steps, config.periods
        ).sample(config.calibration_windows, seed)
    # DAgger rollouts sample actions as the deployed drivers will.
    fit_sampling_noise(net, train, windows, seed, progress)
    stopwatch.lap("noise_before_dagger")

    follow = (
        training_windows(data_dir, 150, config.periods)
        if config.dagger_windows > 0
        else None
    )
    train, dagger_history = dagger_rounds(
        net, train, val, config, seed, follow, progress
    )
    data_meta["train_after_dagger"] = train.summary()
    stopwatch.lap("dagger")

    calibration = fit_sampling_noise(net, train, windows, seed, progress)
    stopwatch.lap("noise")

    closed_loop_history = _closed_loop_stage(net, data_dir, config, seed, progress)
    stopwatch.lap("closed_loop")

    heads, head_history = _ensemble_stage(net, train, config, seed, progress)
    stopwatch.lap("heads")

    prior = fit_xi_prior(heads, config, seed, progress)
    validation = validation_nll(net, val, prior)
    stopwatch.lap("prior")

    report = TrainingReport(
        seed=seed,
        out_dir=str(out),
        files={},
        data=data_meta,
        trunk_history=trunk_history,
        dagger_history=dagger_history,
        closed_loop_history=closed_loop_history,
        head_history=head_history,
        validation=validation,
        calibration=calibration,
        prior=prior.meta,
        config=asdict(config),
        environment=training_environment(),
        seconds=stopwatch.seconds,
    )
    net.guard = config.guard
    return write_training_outputs(out, net, prior, report)
