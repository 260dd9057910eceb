"""Behaviour cloning of the driver network, the bootstrap ensemble and ``P0(xi)``.

Pipeline of :func:`train_drivers` (DESIGN.md §4)::

    demonstrations  = NGSIM I-80 pairs (train split)           longitudinal
                    + NGSIM I-80 lateral pairs (train split)    + lane keeping
                    + IDM+MOBIL in our simulator                lane changes
    trunk + head    = argmin weighted Gaussian NLL  (Adam)      behaviour cloning
    DAgger x K      = learner drives, IDM+MOBIL labels the       covariate shift
                      visited states; refit on the aggregate      (dagger.py)
    heads 1..m      = the head refitted on m bootstrap resamples of the
                      episodes (trunk frozen, so the heads are comparable)
    mu0, Sigma0^-1  = ensemble mean, Ledoit-Wolf + graphical lasso
                      (:mod:`avrisk.learning.glasso`)

The shipped files are ``driver_net.npz`` (trunk + shared head) and
``xi_prior.npz`` (``mu0``, sparse precision, members); see
:mod:`avrisk.agents.drivers.store`. The run is seeded: the same seed, data
and machine give the same files (torch's CPU kernels are deterministic for a
fixed thread count).

Not done here (see the package docstring of :mod:`avrisk.learning`): the
paper trains its generators with model-based GAIL; this is behaviour cloning
with DAgger.
"""

from __future__ import annotations

import hashlib
import json
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.features import FEATURE_NAMES, INDICATOR_FEATURES
from avrisk.agents.drivers.network import ActionDistribution, DriverNet
from avrisk.agents.drivers.store import DRIVER_NET_FILE, XI_PRIOR_FILE, XiPrior
from avrisk.agents.drivers.xi import pack_xi
from avrisk.learning.dagger import (
    dagger_demonstrations,
    replay_dagger_demonstrations,
)
from avrisk.learning.demonstrations import SOURCE_IDM, SOURCE_NAMES, Demonstrations
from avrisk.learning.glasso import fit_sparse_gaussian
from avrisk.learning.ngsim import (
    lateral_pair_split,
    load_i80_lateral,
    load_i80_pairs,
)
from avrisk.learning.ngsim_demonstrations import (
    i80_pair_demonstrations,
    lateral_pair_demonstrations,
)
from avrisk.learning.ngsim_files import I80_LATERAL, I80_PAIRS, ngsim_file
from avrisk.learning.ngsim_lateral import LaneCentres
from avrisk.learning.replay import (
    CarFollowingWindows,
    calibrate_noise,
    car_following_windows,
)
from avrisk.learning.simulated_demonstrations import simulated_demonstrations
from avrisk.sim import Road

__all__ = [
    "TrainConfig",
    "TrainEvent",
    "TrainingReport",
    "behaviour_cloning",
    "bootstrap_heads",
    "fit_action_scale",
    "fit_input_normalization",
    "fit_noise_correlation",
    "imitation_nll",
    "load_demonstrations",
    "train_drivers",
]


@dataclass(frozen=True)
class TrainConfig:
    """Settings of :func:`train_drivers` (the defaults made the shipped files).

    Parameters
    ----------
    n_members : int, default=20
        Ensemble heads ``m``.
    trunk_epochs : int, default=12
        Behaviour-cloning epochs of the whole network.
    head_epochs : int, default=20
        Epochs of every bootstrap head (trunk frozen).
    batch_size : int, default=1024
        Rows per step of behaviour cloning.
    head_batch_size : int, default=4096
        Rows per step of the heads.
    lr : float, default=1e-3
        Adam learning rate of behaviour cloning.
    head_lr : float, default=3e-4
        Adam learning rate of the heads.
    weight_decay : float, default=1e-5
        Adam weight decay.
    n_sim_rollouts : int, default=256
        IDM+MOBIL rollouts for training demonstrations (8 vehicles, 15 s).
    n_sim_val_rollouts : int, default=32
        IDM+MOBIL rollouts for validation (another seed).
    sim_accel_weight : float, default=0.25
        Loss weight of the simulated (non-human) acceleration targets.
    dagger_iters : int, default=4
        DAgger rounds after behaviour cloning (0: plain behaviour cloning).
    dagger_rollouts : int, default=128
        Learner rollouts per round in random traffic (8 vehicles, 15 s).
    dagger_windows : int, default=0
        Learner replays per round of human car-following training windows
        (15 s), labelled by IDM
        (:func:`avrisk.learning.dagger.replay_dagger_demonstrations`). Off by
        default: with 256 per round the IDM labels contradicted the human ones
        on nearly the same states and closed-loop realism got worse.
    dagger_epochs : int, default=3
        Refit epochs per round, on all demonstrations so far.
    dagger_lr : float, default=5e-4
        Adam learning rate of the refits.
    dagger_accel_weight : float, default=0.5
        Loss weight of the expert's acceleration labels on visited states (the
        human data have no emergency braking; only the expert shows it).
    calibration_windows : int, default=160
        Training car-following windows replayed to calibrate the sampling
        noise (:func:`avrisk.learning.replay.calibrate_noise`); 0 skips it and
        keeps the network's own Gaussian (``noise_scale = 1``).
    calibration_steps : int, default=100
        Steps per calibration window.
    target_density : float, default=0.01
        Graphical lasso: fraction of coordinate pairs that may be linked.
    max_shift : float, default=0.01
        CE search box of the ``xi`` block, recorded in the prior's metadata.
    """

    n_members: int = 20
    trunk_epochs: int = 12
    head_epochs: int = 20
    batch_size: int = 1024
    head_batch_size: int = 4096
    lr: float = 1e-3
    head_lr: float = 3e-4
    weight_decay: float = 1e-5
    n_sim_rollouts: int = 256
    n_sim_val_rollouts: int = 32
    sim_accel_weight: float = 0.25
    dagger_iters: int = 4
    dagger_rollouts: int = 128
    dagger_windows: int = 0
    dagger_epochs: int = 3
    dagger_lr: float = 5e-4
    dagger_accel_weight: float = 0.5
    calibration_windows: int = 160
    calibration_steps: int = 100
    target_density: float = 0.01
    max_shift: float = 0.01

    def __post_init__(self) -> None:
        if self.n_members < 2:
            raise ValueError(f"n_members must be >= 2; got {self.n_members}")
        for name in ("trunk_epochs", "head_epochs", "batch_size", "head_batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")


class TrainEvent(NamedTuple):
    """One progress report of :func:`train_drivers`.

    Attributes
    ----------
    stage : str
        ``"data"``, ``"trunk"``, ``"dagger"``, ``"noise"``, ``"heads"`` or
        ``"prior"``.
    step : int
        Steps of the stage done.
    total : int
        Steps of the stage.
    metrics : dict of str to float
        E.g. the training loss and validation NLLs.
    """

    stage: str
    step: int
    total: int
    metrics: dict[str, float]


Progress = Callable[[TrainEvent], None]


@dataclass(frozen=True)
class TrainingReport:
    """What :func:`train_drivers` did and measured (JSON-serialisable).

    Attributes
    ----------
    seed : int
    out_dir : str
    files : dict of str to int
        Written files and their sizes [bytes].
    data : dict
        Input files (sha256) and demonstrations per source.
    trunk_history : list of dict
        Per epoch: training loss, validation NLL per source and target.
    dagger_history : list of dict
        Per DAgger round: rows added and the last refit epoch's losses.
    head_history : list of dict
        Per head epoch: mean training loss over the heads.
    validation : dict
        Validation NLL of the shared head and of ``mu0``, per source/target.
    calibration : dict
        Sampling-noise scale chosen on replays of training windows, and the
        distances of every candidate.
    prior : dict
        Graphical-lasso fit (:meth:`SparseGaussianFit.to_meta`).
    config : dict
    environment : dict
        Versions and thread count.
    seconds : dict of str to float
        Wall time per stage.
    """

    seed: int
    out_dir: str
    files: dict[str, int]
    data: dict[str, Any]
    trunk_history: list[dict[str, float]]
    dagger_history: list[dict[str, float]]
    head_history: list[dict[str, float]]
    validation: dict[str, Any]
    calibration: dict[str, Any]
    prior: dict[str, Any]
    config: dict[str, Any]
    environment: dict[str, Any]
    seconds: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return asdict(self)


# ----------------------------------------------------------------- scaling
def fit_input_normalization(
    features: NDArray[Any],
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Per-feature centre and scale for the network's input standardisation.

    Indicators keep centre 0 and scale 1; constant features get scale 1.

    Parameters
    ----------
    features : ndarray of shape (N, N_FEATURES)

    Returns
    -------
    mean, scale : ndarray of float32, shape (N_FEATURES,)
    """
    x = np.asarray(features, dtype=np.float64)
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale = np.where(scale > 1e-6, scale, 1.0)
    for name in INDICATOR_FEATURES:
        k = FEATURE_NAMES.index(name)
        mean[k], scale[k] = 0.0, 1.0
    return mean.astype(np.float32), scale.astype(np.float32)


def fit_action_scale(demos: Demonstrations) -> tuple[float, float]:
    """Weighted standard deviations of the targets ``(s_a [m/s^2], s_s [rad])``."""

    def wstd(y: NDArray[Any], w: NDArray[Any], fallback: float) -> float:
        if w.sum() <= 0:
            return fallback
        mu = np.average(y, weights=w)
        return float(
            max(np.sqrt(np.average((y - mu) ** 2, weights=w)), 1e-3 * fallback)
        )

    return wstd(demos.accel, demos.accel_weight, 1.0), wstd(
        demos.steer, demos.steer_weight, 0.02
    )


# -------------------------------------------------------------------- loss
def _weighted_nll(
    dist: ActionDistribution,
    accel: torch.Tensor,
    steer: torch.Tensor,
    w_accel: torch.Tensor,
    w_steer: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Sum of weighted NLLs and sum of weights (both broadcast over heads)."""
    lp_a, lp_s = dist.log_prob(accel, steer)
    total = -(w_accel * lp_a + w_steer * lp_s).sum(-1)
    return total, (w_accel + w_steer).sum(-1)


def _tensors(demos: Demonstrations) -> dict[str, torch.Tensor]:
    return {
        "features": torch.from_numpy(np.ascontiguousarray(demos.features, np.float32)),
        "accel": torch.from_numpy(demos.accel.astype(np.float32)),
        "steer": torch.from_numpy(demos.steer.astype(np.float32)),
        "w_accel": torch.from_numpy(demos.accel_weight.astype(np.float32)),
        "w_steer": torch.from_numpy(demos.steer_weight.astype(np.float32)),
    }


def imitation_nll(
    net: DriverNet,
    demos: Demonstrations,
    xi: torch.Tensor | None = None,
    *,
    batch: int = 65536,
) -> dict[str, float]:
    """Mean Gaussian negative log-likelihood of the demonstrated actions.

    Parameters
    ----------
    net : DriverNet
    demos : Demonstrations
    xi : Tensor of shape (XI_DIM,), optional
        Last layer; default the network's own.
    batch : int, default=65536
        Rows per forward pass.

    Returns
    -------
    dict of str to float
        ``"<source>/accel"`` and ``"<source>/steer"`` NLL per row with a target
        [nats], for each source present, and ``"loss"``: the weighted mean
        that training minimises.
    """
    t = _tensors(demos)
    n = len(demos)
    lp_a = torch.empty(n)
    lp_s = torch.empty(n)
    with torch.no_grad():
        for s in range(0, n, batch):
            dist = net(t["features"][s : s + batch], xi)
            a, b = dist.log_prob(t["accel"][s : s + batch], t["steer"][s : s + batch])
            lp_a[s : s + batch], lp_s[s : s + batch] = a, b
    wa, ws = t["w_accel"], t["w_steer"]
    out = {
        "loss": float(-(wa * lp_a + ws * lp_s).sum() / (wa + ws).sum().clamp_min(1e-12))
    }
    for code, name in SOURCE_NAMES.items():
        m = torch.from_numpy(demos.source == code)
        for target, lp, w in (("accel", lp_a, wa), ("steer", lp_s, ws)):
            sel = m & (w > 0)
            if bool(sel.any()):
                out[f"{name}/{target}"] = float(-lp[sel].mean())
    return out


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
    t = _tensors(d)
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


# ------------------------------------------------------- behaviour cloning
def behaviour_cloning(
    net: DriverNet,
    demos: Demonstrations,
    *,
    epochs: int = 12,
    batch_size: int = 1024,
    lr: float = 1e-3,
    weight_decay: float = 1e-5,
    seed: int = 0,
    val: Demonstrations | None = None,
    progress: Progress | None = None,
) -> list[dict[str, float]]:
    """Fit the whole network to demonstrations by weighted Gaussian NLL (Adam).

    Parameters
    ----------
    net : DriverNet
        Trained in place (its input and action scales are kept).
    demos : Demonstrations
    epochs, batch_size : int
    lr, weight_decay : float
        Adam settings.
    seed : int, default=0
        Seeds the shuffling.
    val : Demonstrations, optional
        Evaluated after every epoch (:func:`imitation_nll`).
    progress : callable, optional
        Receives a :class:`TrainEvent` after every epoch.

    Returns
    -------
    list of dict
        Per epoch: ``"epoch"``, ``"train_loss"`` and ``"val/..."`` entries.
    """
    t = _tensors(demos)
    n = len(demos)
    gen = torch.Generator().manual_seed(seed)
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs)
    history = []
    net.train()
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        total, weight = 0.0, 0.0
        for s in range(0, n, batch_size):
            idx = perm[s : s + batch_size]
            dist = net(t["features"][idx])
            nll, w = _weighted_nll(
                dist,
                t["accel"][idx],
                t["steer"][idx],
                t["w_accel"][idx],
                t["w_steer"][idx],
            )
            loss = nll / w.clamp_min(1e-12)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(nll.detach())
            weight += float(w)
        sched.step()
        row = {"epoch": float(epoch + 1), "train_loss": total / max(weight, 1e-12)}
        if val is not None:
            net.eval()
            row.update({f"val/{k}": v for k, v in imitation_nll(net, val).items()})
            net.train()
        history.append(row)
        if progress is not None:
            progress(TrainEvent("trunk", epoch + 1, epochs, row))
    net.eval()
    return history


def _bootstrap_counts(
    episode: NDArray[np.int64],
    source: NDArray[np.int8],
    n_members: int,
    rng: np.random.Generator,
) -> NDArray[np.float32]:
    """Per-member row multiplicities from resampling episodes within each source."""
    uniq, inverse = np.unique(episode, return_inverse=True)
    ep_source = np.zeros(len(uniq), np.int8)
    ep_source[inverse] = source
    counts = np.zeros((n_members, len(uniq)), np.float32)
    for code in np.unique(ep_source):
        eps = np.flatnonzero(ep_source == code)
        for k in range(n_members):
            draw = rng.integers(0, len(eps), len(eps))
            np.add.at(counts[k], eps[draw], 1.0)
    return counts[:, inverse]  # (m, N)


def bootstrap_heads(
    net: DriverNet,
    demos: Demonstrations,
    n_members: int = 20,
    *,
    epochs: int = 20,
    batch_size: int = 4096,
    lr: float = 3e-4,
    seed: int = 0,
    progress: Progress | None = None,
) -> tuple[NDArray[np.float64], list[dict[str, float]]]:
    """Refit the last layer on ``m`` bootstrap resamples, trunk frozen.

    Episodes (not rows) are resampled with replacement within each source; all
    heads start from the network's head and see the same minibatch sequence,
    so they differ only through their resample. All heads train together: one
    ``(m, n, 100) x (m, 100, 4)`` product per step.

    Parameters
    ----------
    net : DriverNet
        Trained trunk; not modified.
    demos : Demonstrations
    n_members : int, default=20
    epochs, batch_size : int
    lr : float
        Adam learning rate.
    seed : int, default=0
    progress : callable, optional
        Receives a :class:`TrainEvent` after every epoch.

    Returns
    -------
    heads : ndarray of shape (m, XI_DIM)
        Each member's ``xi``.
    history : list of dict
        Per epoch: ``"epoch"``, ``"train_loss"`` (mean over heads).
    """
    rng = np.random.default_rng(seed)
    t = _tensors(demos)
    n = len(demos)
    with torch.no_grad():
        hidden = torch.cat(
            [net.trunk(t["features"][s : s + 65536]) for s in range(0, n, 65536)]
        )
    mult = torch.from_numpy(
        _bootstrap_counts(demos.episode, demos.source, n_members, rng)
    )
    weight = net.last.weight.detach().clone().expand(n_members, -1, -1).contiguous()
    bias = net.last.bias.detach().clone().expand(n_members, -1).contiguous()
    weight.requires_grad_(True)
    bias.requires_grad_(True)
    opt = torch.optim.Adam([weight, bias], lr=lr)
    gen = torch.Generator().manual_seed(seed + 1)
    history = []
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        total = 0.0
        steps = 0
        for s in range(0, n, batch_size):
            idx = perm[s : s + batch_size]
            raw = torch.einsum("nh,moh->mno", hidden[idx], weight) + bias[:, None, :]
            dist = net.distribution(raw)
            m = mult[:, idx]
            nll, w = _weighted_nll(
                dist,
                t["accel"][idx],
                t["steer"][idx],
                m * t["w_accel"][idx],
                m * t["w_steer"][idx],
            )
            loss = (nll / w.clamp_min(1e-12)).sum()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += float(loss.detach()) / n_members
            steps += 1
        row = {"epoch": float(epoch + 1), "train_loss": total / max(steps, 1)}
        history.append(row)
        if progress is not None:
            progress(TrainEvent("heads", epoch + 1, epochs, row))
    heads = pack_xi(weight.detach(), bias.detach()).to(torch.float64).numpy()
    return heads, history


# ------------------------------------------------------------------- data
def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_demonstrations(
    data_dir: str | Path | None,
    seed: int,
    config: TrainConfig = TrainConfig(),
    road: Road | None = None,
) -> tuple[Demonstrations, Demonstrations, dict[str, Any]]:
    """Training and validation demonstrations from NGSIM and the simulator.

    Parameters
    ----------
    data_dir : str or Path or None
        NGSIM folder (:func:`avrisk.learning.ngsim_files.ngsim_dir`; None: the data
        shipped with the package), packed or original files.
    seed : int
        Seeds the simulated scenes (validation uses ``seed + 1``).
    config : TrainConfig
    road : Road, optional
        Default the scenario road ``Road()`` (6 lanes of 3.7 m).

    Returns
    -------
    train, val : Demonstrations
        NGSIM train splits + IDM+MOBIL; NGSIM test splits + IDM+MOBIL (other
        seed).
    meta : dict
        Files and their sha256, lane centres, per-source counts.
    """
    road = Road() if road is None else road
    files = [ngsim_file(names, data_dir) for names in (I80_PAIRS, I80_LATERAL)]
    pairs = load_i80_pairs(files[0])
    lateral = load_i80_lateral(files[1])
    split = lateral_pair_split(lateral, pairs)
    centres = LaneCentres.fit(lateral.take(split == "train"))
    offsets = iter(range(0, 10_000_000, 1_000_000))
    parts: dict[str, list[Demonstrations]] = {"train": [], "test": []}
    for name in ("train", "test"):
        parts[name].append(
            i80_pair_demonstrations(
                pairs.take(pairs.split == name), road, episode_offset=next(offsets)
            )
        )
        parts[name].append(
            lateral_pair_demonstrations(
                lateral.take(split == name),
                road,
                centres=centres,
                episode_offset=next(offsets),
            )
        )
    parts["train"].append(
        simulated_demonstrations(
            config.n_sim_rollouts,
            seed,
            road=road,
            accel_weight=config.sim_accel_weight,
            episode_offset=next(offsets),
        )
    )
    parts["test"].append(
        simulated_demonstrations(
            config.n_sim_val_rollouts,
            seed + 1,
            road=road,
            accel_weight=config.sim_accel_weight,
            episode_offset=next(offsets),
        )
    )
    train = Demonstrations.concat(parts["train"])
    val = Demonstrations.concat(parts["test"])
    meta = {
        "files": {f.name: _sha256(f) for f in files},
        "lane_centres_m": centres.to_dict(),
        "train": train.summary(),
        "val": val.summary(),
    }
    return train, val, meta


def training_windows(data_dir: str | Path | None, n_steps: int) -> CarFollowingWindows:
    """Car-following windows of the training splits (for noise calibration)."""
    pairs = load_i80_pairs(ngsim_file(I80_PAIRS, data_dir))
    lateral = load_i80_lateral(ngsim_file(I80_LATERAL, data_dir))
    split = lateral_pair_split(lateral, pairs)
    train_lat = lateral.take(split == "train")
    return car_following_windows(
        pairs.take(pairs.split == "train"),
        train_lat,
        LaneCentres.fit(train_lat),
        n_steps,
        Road(),
    )


# ---------------------------------------------------------------- top level
def train_drivers(
    seed: int = 0,
    out_dir: str | Path = "drivers",
    *,
    data_dir: str | Path | None = None,
    config: TrainConfig = TrainConfig(),
    progress: Progress | None = None,
    threads: int | None = 1,
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
        with the package (:func:`avrisk.learning.ngsim_files.ngsim_dir`).
    config : TrainConfig
    progress : callable, optional
        Receives :class:`TrainEvent` reports (for a progress bar).
    threads : int or None, default=1
        torch CPU threads during the run (restored afterwards). With one
        thread the run is bit-reproducible on a machine; a multi-threaded BLAS
        may split reductions differently from run to run. None keeps the
        current setting.

    Returns
    -------
    TrainingReport
    """
    previous = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        return _train_drivers(seed, Path(out_dir), data_dir, config, progress)
    finally:
        torch.set_num_threads(previous)


def _train_drivers(
    seed: int,
    out: Path,
    data_dir: str | Path | None,
    config: TrainConfig,
    progress: Progress | None,
) -> TrainingReport:
    clock = {"start": time.perf_counter()}
    seconds: dict[str, float] = {}

    def lap(name: str) -> None:
        now = time.perf_counter()
        seconds[name] = round(now - clock["start"], 2)
        clock["start"] = now

    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    train, val, data_meta = load_demonstrations(data_dir, seed, config)
    if progress is not None:
        progress(
            TrainEvent("data", 1, 1, {"train_rows": len(train), "val_rows": len(val)})
        )
    lap("data")

    mean, scale = fit_input_normalization(train.features)
    net = DriverNet(mean, scale, fit_action_scale(train))
    trunk_history = behaviour_cloning(
        net,
        train,
        epochs=config.trunk_epochs,
        batch_size=config.batch_size,
        lr=config.lr,
        weight_decay=config.weight_decay,
        seed=seed,
        val=val,
        progress=progress,
    )
    lap("trunk")

    windows = None
    if config.calibration_windows > 0:
        windows = training_windows(data_dir, config.calibration_steps)
        pick = np.random.default_rng(seed).permutation(len(windows))
        windows = windows.take(np.sort(pick[: config.calibration_windows]))

    def fit_noise(stage: str) -> dict[str, Any]:
        """Noise persistence from human residuals, then its scale by replays."""
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
            progress(TrainEvent(stage, 1, 1, metrics))
        return out

    # DAgger rollouts sample actions as the deployed drivers will.
    fit_noise("noise")
    lap("noise_before_dagger")

    follow = training_windows(data_dir, 150) if config.dagger_windows > 0 else None
    dagger_history = []
    for k in range(config.dagger_iters):
        visited = dagger_demonstrations(
            net,
            config.dagger_rollouts,
            seed * 1000 + 10 + k,
            accel_weight=config.dagger_accel_weight,
            episode_offset=(100 + k) * 1_000_000,
        )
        if follow is not None:
            pick = np.random.default_rng(seed * 1000 + 500 + k).permutation(len(follow))
            followed = replay_dagger_demonstrations(
                net,
                follow.take(np.sort(pick[: config.dagger_windows])),
                seed * 1000 + 500 + k,
                accel_weight=config.dagger_accel_weight,
                episode_offset=(200 + k) * 1_000_000,
            )
            visited = Demonstrations.concat([visited, followed])
        train = Demonstrations.concat([train, visited])
        refit = behaviour_cloning(
            net,
            train,
            epochs=config.dagger_epochs,
            batch_size=config.batch_size,
            lr=config.dagger_lr,
            weight_decay=config.weight_decay,
            seed=seed + 1 + k,
            val=val,
        )
        row = {"round": float(k + 1), "rows_added": float(len(visited)), **refit[-1]}
        dagger_history.append(row)
        if progress is not None:
            progress(TrainEvent("dagger", k + 1, config.dagger_iters, row))
    data_meta["train_after_dagger"] = train.summary()
    lap("dagger")

    calibration = fit_noise("noise")
    lap("noise")

    heads, head_history = bootstrap_heads(
        net,
        train,
        config.n_members,
        epochs=config.head_epochs,
        batch_size=config.head_batch_size,
        lr=config.head_lr,
        seed=seed,
        progress=progress,
    )
    lap("heads")

    fit = fit_sparse_gaussian(heads, target_density=config.target_density)
    mu0 = torch.as_tensor(fit.mean, dtype=torch.float32)
    validation = {
        "shared_head": imitation_nll(net, val),
        "mu0": imitation_nll(net, val, mu0),
        "members": [
            imitation_nll(net, val, torch.as_tensor(h, dtype=torch.float32))["loss"]
            for h in heads
        ],
    }
    prior_meta = {
        **fit.to_meta(),
        "seed": seed,
        "max_shift": config.max_shift,
        "member_std_median": float(np.median(heads.std(axis=0, ddof=1))),
        "member_std_max": float(heads.std(axis=0, ddof=1).max()),
    }
    if progress is not None:
        progress(
            TrainEvent("prior", 1, 1, {"sparsity": fit.sparsity, "alpha": fit.alpha})
        )
    lap("prior")

    net.save(out / DRIVER_NET_FILE)
    XiPrior(
        mean=fit.mean, precision=fit.precision, members=heads, meta=prior_meta
    ).save(out / XI_PRIOR_FILE)
    import sklearn

    report = TrainingReport(
        seed=seed,
        out_dir=str(out),
        files={},
        data=data_meta,
        trunk_history=trunk_history,
        dagger_history=dagger_history,
        head_history=head_history,
        validation=validation,
        calibration=calibration,
        prior=prior_meta,
        config=asdict(config),
        environment={
            "python": platform.python_version(),
            "torch": torch.__version__,
            "numpy": np.__version__,
            "scikit-learn": sklearn.__version__,
            "torch_threads": torch.get_num_threads(),
            "machine": platform.machine(),
        },
        seconds=seconds,
    )
    files = {f: (out / f).stat().st_size for f in (DRIVER_NET_FILE, XI_PRIOR_FILE)}
    report = TrainingReport(**{**report.__dict__, "files": files})
    (out / "training_report.json").write_text(json.dumps(report.to_dict(), indent=2))
    return report
