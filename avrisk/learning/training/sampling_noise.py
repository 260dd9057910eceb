"""The learned drivers' sampling noise: its persistence and its scale.

A :class:`~avrisk.agents.drivers.driver.LearnedDriver` samples its actions
from the network's Gaussian with AR(1) noise over steps. The AR(1)
coefficient per action comes from the human residuals
(:func:`fit_noise_correlation`); how much of the network's standard deviation
to sample (``noise_scale``) is chosen by closed-loop replays of human
car-following windows (:func:`calibrate_noise`). :func:`fit_sampling_noise`
does both, the noise stage of :func:`~avrisk.learning.training.train.train_drivers`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from avrisk.agents.drivers.driver import LearnedDriver
from avrisk.agents.drivers.network import DriverNet
from avrisk.learning.imitation.demonstrations import SOURCE_IDM, Demonstrations
from avrisk.learning.imitation.loss import demonstration_tensors
from avrisk.learning.replay import CarFollowingWindows, replay, replay_distances
from avrisk.learning.train_config import Progress, TrainEvent
from avrisk.sim import Road

__all__ = ["calibrate_noise", "fit_noise_correlation", "fit_sampling_noise"]


def fit_noise_correlation(
    net: DriverNet, demos: Demonstrations, *, max_rho: float = 0.98
) -> tuple[float, float]:
    """Lag-1 autocorrelation of the standardised residuals of human actions.

    For every pair of consecutive rows of one human episode (NGSIM sources),
    ``r_t = (y_t - mean_t) / std_t`` under the network; the pooled correlation
    of ``(r_t, r_{t+1})`` per action is the AR(1) coefficient with which
    :class:`~avrisk.agents.drivers.driver.LearnedDriver` correlates its
    sampling noise over steps.

    Parameters
    ----------
    net : DriverNet
    demos : Demonstrations
        Human rows must be consecutive time steps within an episode (as built).
    max_rho : float, default=0.98
        Upper clip (the steering targets come from smoothed tracks, whose
        residuals are correlated by the smoothing itself).

    Returns
    -------
    rho_accel, rho_steer : float
        In ``[0, max_rho]``; 0 where no human target exists.
    """
    human = demos.source != SOURCE_IDM
    d = demos.take(human)
    if len(d) < 2:
        return 0.0, 0.0
    t = demonstration_tensors(d)
    with torch.no_grad():
        dist = net(t["features"])
    out = []
    same = d.episode[1:] == d.episode[:-1]
    for y, mean, log_var, w in (
        (t["accel"], dist.accel_mean, dist.accel_log_var, d.accel_weight),
        (t["steer"], dist.steer_mean, dist.steer_log_var, d.steer_weight),
    ):
        r = ((y - mean) * torch.exp(-0.5 * log_var)).numpy().astype(np.float64)
        ok = same & (w[1:] > 0) & (w[:-1] > 0)
        if not ok.any():
            out.append(0.0)
            continue
        a, b = r[:-1][ok], r[1:][ok]
        rho = float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))
        out.append(float(np.clip(rho, 0.0, max_rho)))
    return out[0], out[1]


def calibrate_noise(
    net: DriverNet,
    windows: CarFollowingWindows,
    road: Road,
    *,
    grid: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3, 0.5, 1.0),
    crash_penalty: float = 5.0,
    seed: int = 0,
) -> tuple[tuple[float, float], list[dict[str, float]]]:
    """Choose ``net.noise_scale`` by closed-loop replays of human windows.

    Coordinate search over ``grid``: first the acceleration scale (steering
    noise off) by ``KS(accel) + KS(jerk) + KS(speed) + KS(gap) +
    crash_penalty * crash_rate``, then the steering scale (acceleration scale
    fixed) by ``KS(offset) + crash_penalty * crash_rate``. The network's
    ``noise_correlation`` is used as it is.

    Parameters
    ----------
    net : DriverNet
        Its ``noise_scale`` is set to the result.
    windows : CarFollowingWindows
        Training windows (never the evaluation ones).
    road : Road
    grid : tuple of float
        Candidate scales.
    crash_penalty : float, default=5.0
        Weight of the collision rate in both objectives.
    seed : int, default=0

    Returns
    -------
    scale : tuple of float
        ``(c_accel, c_steer)``.
    trials : list of dict
        Every evaluated candidate with its distances.
    """
    done: dict[tuple[float, float], dict[str, float]] = {}

    def run(c_a: float, c_s: float) -> dict[str, float]:
        if (c_a, c_s) not in done:
            net.noise_scale.copy_(torch.tensor([c_a, c_s]))
            both = torch.ones(2, dtype=torch.bool)
            res = replay(windows, LearnedDriver(net, controlled=both), road, seed=seed)
            done[c_a, c_s] = {
                "c_accel": c_a,
                "c_steer": c_s,
                **replay_distances(windows, res),
            }
        return done[c_a, c_s]

    def longitudinal(r: dict[str, float]) -> float:
        return (
            r["accel"]
            + r["jerk"]
            + r["speed"]
            + r["gap"]
            + crash_penalty * r["crash_rate"]
        )

    def lateral(r: dict[str, float]) -> float:
        return r.get("offset", 0.0) + crash_penalty * r["crash_rate"]

    best_a = min(grid, key=lambda c: longitudinal(run(c, 0.0)))
    best_s = min(grid, key=lambda c: lateral(run(best_a, c)))
    net.noise_scale.copy_(torch.tensor([best_a, best_s]))
    return (float(best_a), float(best_s)), list(done.values())


def fit_sampling_noise(
    net: DriverNet,
    train: Demonstrations,
    windows: CarFollowingWindows | None,
    seed: int,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Set the noise persistence from human residuals, then its scale by replays.

    Parameters
    ----------
    net : DriverNet
        Its ``noise_correlation`` and (with ``windows``) ``noise_scale`` are set.
    train : Demonstrations
        Training demonstrations (:func:`fit_noise_correlation`).
    windows : CarFollowingWindows or None
        Training windows for :func:`calibrate_noise`; None keeps the scale.
    seed : int
        Seeds the replays.
    progress : callable, optional
        Receives a ``"noise"`` :class:`TrainEvent`.

    Returns
    -------
    dict
        ``"noise_correlation"``, ``"noise_scale"`` (``[1, 1]`` without
        windows) and, with windows, their number and the calibration trials.
    """
    rho = fit_noise_correlation(net, train)
    net.noise_correlation.copy_(torch.tensor(rho))
    out: dict[str, Any] = {
        "noise_correlation": list(rho),
        "noise_scale": [1.0, 1.0],
    }
    if windows is not None:
        scale, trials = calibrate_noise(net, windows, Road(), seed=seed)
        out.update(noise_scale=list(scale), windows=len(windows), trials=trials)
    if progress is not None:
        metrics = {"rho_accel": rho[0], "rho_steer": rho[1]}
        metrics.update(c_accel=out["noise_scale"][0], c_steer=out["noise_scale"][1])
        progress(TrainEvent("noise", 1, 1, metrics))
    return out
