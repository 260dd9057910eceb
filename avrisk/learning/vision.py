"""Training PilotNet: imitate the lidar ego's steering on rendered images, with DAgger.

Pipeline of :func:`train_vision`::

    round 0   the lidar ego drives P0's scenes, its steering perturbed; every
              few steps the camera image and the lidar ego's steering are
              recorded                           (behaviour cloning with DART)
    round k   PilotNet steers (perturbed alike; the lidar net throttles); the
              lidar ego labels the images of the states PilotNet visits
                                                           (DAgger, k = 1..K)
    fit       after every round, Adam on the Huber loss of the standardised
              steering, over all rounds' frames
    report    steering error on held-out scenes (the lidar ego drives), and
              closed-loop lane keeping, road departures and crashes from P0,
              PilotNet ego next to the lidar ego on the same scenes

The expert is :class:`~avrisk.agents.drivers.LearnedEgoPolicy` (the shipped
lidar ego, ``lidar_imitation``), as the paper's arrangement suggests: the
vision ego's throttle is that network's, and its steering learns the same
network's steering from pixels. Images are kept as 8-bit RGB (the renderer's
flat colours lose nothing visible). The run is seeded, with one torch thread
by default: the same seed and machine give the same weights.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from avrisk.agents.drivers import LearnedEgoPolicy
from avrisk.agents.drivers.driver import LearnedState
from avrisk.agents.vision import PilotNet, PilotNetEgo
from avrisk.agents.vision.store import PILOTNET_FILE
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution
from avrisk.learning.train_config import Progress, TrainEvent
from avrisk.learning.training.report import training_environment
from avrisk.scenario import load_spec
from avrisk.scenario.components import EgoSpec
from avrisk.scenario.sensors import CameraSpec
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = ["VisionTrainConfig", "collect_frames", "train_vision"]

#: The report written next to the weights.
REPORT_FILE = "training_report.json"
#: Step-to-step correlation of the steering perturbation during data collection.
NOISE_CORRELATION = 0.9


@dataclass(frozen=True)
class VisionTrainConfig:
    """Settings of :func:`train_vision` (defaults: the shipped weights).

    Parameters
    ----------
    scenario : str, default="highway_vision"
        Bundled scenario (or file) whose scenes, camera and P0 are used.
    rollouts : int, default=48
        Scenes per round of data.
    frame_every : int, default=4
        Record one frame every this many steps.
    steer_noise : float, default=0.03
        Standard deviation of the steering perturbation while collecting
        [rad] (:func:`collect_frames`). Without it the lidar ego keeps the lane
        centre to a few centimetres and a degree, and its images hold almost
        nothing to learn from (the fit stays at the labels' mean).
    dagger_rounds : int, default=2
        Rounds in which PilotNet drives and the lidar ego labels.
    epochs : int, default=6
        Passes over all frames gathered so far, after every round.
    batch_size : int, default=32
    lr : float, default=1e-3
        Adam's step size.
    val_rollouts : int, default=16
        Held-out scenes for the steering error.
    eval_rollouts : int, default=64
        Scenes from P0 for the closed-loop report.
    horizon : float or None, default=None
        Rollout length [s]; None keeps the scenario's.
    """

    scenario: str = "highway_vision"
    rollouts: int = 48
    frame_every: int = 4
    steer_noise: float = 0.03
    dagger_rounds: int = 2
    epochs: int = 6
    batch_size: int = 32
    lr: float = 1e-3
    val_rollouts: int = 16
    eval_rollouts: int = 64
    horizon: float | None = None


class _Recorder:
    """The ego during data collection: drives, and records images and labels.

    The lidar ego gives the throttle and the steering label; ``learner`` (if
    any) steers instead of it. Eager only: it appends to Python lists.
    """

    reads_lidar = True
    reads_camera = True
    noise = None

    def __init__(
        self,
        expert: LearnedEgoPolicy,
        learner: PilotNet | None,
        every: int,
        steer_noise: float,
        gen: torch.Generator,
        max_steer: float,
    ) -> None:
        self.expert = expert
        self.max_steer = max_steer
        self.learner = learner
        self.every = every
        self.steer_noise = steer_noise
        self.gen = gen
        self.controlled = expert.controlled
        self.images: list[Tensor] = []
        self.labels: list[Tensor] = []
        self._noise: Tensor | None = None

    def init(self, obs: Observation, params: Tensor | None) -> LearnedState:
        return self.expert.init(obs, params)

    def act(
        self, obs: Observation, state: LearnedState, noise: None
    ) -> tuple[Action, LearnedState]:
        assert obs.camera is not None
        action, state = self.expert.act(obs, state, None)
        rgb = obs.camera.rgb
        if int(obs.step) % self.every == 0:
            self.images.append(_to_bytes(rgb))
            label = action.steer[:, 0].clamp(-self.max_steer, self.max_steer)
            self.labels.append(label.float().cpu())
        steer = action.steer[:, 0]
        if self.learner is not None:
            steer = self.learner.steer(rgb).to(steer.dtype)
        steer = steer + self._perturbation(steer)
        return Action(action.accel, steer.unsqueeze(-1).expand_as(action.steer)), state

    def _perturbation(self, steer: Tensor) -> Tensor:
        """AR(1) steering noise, sd ``steer_noise`` [rad], per rollout (B,)."""
        z = torch.randn(steer.shape, generator=self.gen).to(steer)
        if self._noise is None or self._noise.shape != steer.shape:
            self._noise = self.steer_noise * z
        else:
            rho = NOISE_CORRELATION
            self._noise = rho * self._noise + (1 - rho**2) ** 0.5 * self.steer_noise * z
        return self._noise


def _to_bytes(rgb: Tensor) -> Tensor:
    """RGB in [0, 1] (B, 3, H, W) as uint8 on the CPU."""
    return torch.round(rgb * 255.0).to(torch.uint8).cpu()


def _from_bytes(images: Tensor) -> Tensor:
    """uint8 RGB back to float32 in [0, 1]."""
    return images.float() / 255.0


def _with_lidar_ego(spec: ScenarioSpec, horizon: float | None) -> ScenarioSpec:
    """The scenario with the lidar ego (the expert) and its camera kept."""
    update: dict[str, Any] = {"ego": EgoSpec(policy="lidar_imitation")}
    if spec.camera is None:
        update["camera"] = CameraSpec()
    if horizon is not None:
        update["simulation"] = spec.simulation.model_copy(update={"horizon": horizon})
    return spec.model_copy(update=update)


def collect_frames(
    sim: ScenarioSimulator,
    x: np.ndarray,
    seeds: np.ndarray,
    learner: PilotNet | None,
    every: int,
    *,
    steer_noise: float = 0.0,
    seed: int = 0,
) -> tuple[Tensor, Tensor]:
    """Camera images and the lidar ego's steering along rollouts of a scenario.

    Parameters
    ----------
    sim : ScenarioSimulator
        Built with a camera and the ``lidar_imitation`` ego (the expert).
    x : ndarray of shape (B, D)
        Scenes (samples of the scenario's ``X``).
    seeds : ndarray of int64, shape (B,)
    learner : PilotNet or None
        Steers the ego when given (DAgger); None lets the expert drive.
    every : int
        Record every ``every``-th step, ``t = 0, every, ...``.
    steer_noise : float, default=0.0
        Standard deviation [rad] of an AR(1) perturbation (step correlation
        :data:`NOISE_CORRELATION`) added to the steering that is carried out,
        not to the labels (DART, Laskey et al. 2017): the ego leaves the lane
        centre and the labels show how to come back.
    seed : int, default=0
        Seeds the perturbation.

    Returns
    -------
    images : Tensor of uint8, shape (N, 3, H, W)
    labels : Tensor of shape (N,)
        The expert's steering [rad] at each image, clipped to the simulator's
        steering limit (what would be carried out).
    """
    expert = sim.ego_policy
    if not isinstance(expert, LearnedEgoPolicy):
        raise TypeError("collect_frames needs a scenario built with the lidar ego")
    gen = torch.Generator().manual_seed(seed)
    max_steer = sim.config.max_steer
    recorder = _Recorder(expert, learner, every, steer_noise, gen, max_steer)
    sim.ego_policy = recorder
    try:
        sim.rollout(x, seeds)
    finally:
        sim.ego_policy = expert
    return torch.cat(recorder.images), torch.cat(recorder.labels)


def _fit(
    net: PilotNet,
    images: Tensor,
    labels: Tensor,
    config: VisionTrainConfig,
    gen: torch.Generator,
    optimizer: torch.optim.Optimizer,
    progress: Progress | None,
    round_: int,
) -> list[float]:
    """Epochs of Adam on the standardised steering; mean loss per epoch.

    The loss is Huber's (quadratic within one label standard deviation, linear
    beyond): the labels of the states a poor learner visits in DAgger can be
    tens of standard deviations out, and would dominate a squared error.
    """
    net.train()
    target = (labels - net.steer_mean) / net.steer_scale
    history = []
    for epoch in range(config.epochs):
        order = torch.randperm(len(labels), generator=gen)
        total = 0.0
        for batch in order.split(config.batch_size):
            loss = F.huber_loss(net(_from_bytes(images[batch])), target[batch])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item() * len(batch)
        history.append(total / len(labels))
        if progress is not None:
            step = round_ * config.epochs + epoch + 1
            progress(
                TrainEvent(
                    "fit",
                    step,
                    (config.dagger_rounds + 1) * config.epochs,
                    {"train_loss": history[-1], "frames": float(len(labels))},
                )
            )
    net.eval()
    return history


@torch.no_grad()
def _steering_error(net: PilotNet, images: Tensor, labels: Tensor) -> dict[str, float]:
    """RMSE of PilotNet's steering on held-out frames [rad], and the labels' spread."""
    pred = torch.cat([net.steer(_from_bytes(part)) for part in images.split(256)])
    return {
        "rmse_rad": float(torch.sqrt(torch.mean((pred - labels) ** 2))),
        "label_sd_rad": float(labels.std(correction=0)),
        "frames": float(len(labels)),
    }


def _lane_keeping(sim: ScenarioSimulator, x: np.ndarray, seeds: np.ndarray) -> dict:
    """Closed-loop crash, road-departure and lane-offset figures of one ego."""
    res = sim.rollout(x, seeds, record_trace=True)
    trace = res.trace
    assert trace is not None
    lane_width = sim.road.lane_width
    y = trace.y[:, :, 0]
    offset = y - (torch.floor(y / lane_width) + 0.5) * lane_width
    alive = trace.alive
    return {
        "crash_rate": float(res.crash.float().mean()),
        "offroad_rate": float(res.offroad.float().mean()),
        "mean_abs_lane_offset_m": float(offset.abs()[alive].mean()),
        "max_abs_lane_offset_m": float(offset.abs()[alive].max()),
        "median_f_s": float(res.f.median()),
    }


def _closed_loop(
    sim: ScenarioSimulator, net: PilotNet, x: np.ndarray, seeds: np.ndarray
) -> dict[str, dict]:
    """Lane keeping of the lidar ego, then of PilotNet steering it, on the same scenes.

    ``sim``'s ego becomes the PilotNet ego.
    """
    closed_loop = {"lidar_imitation": _lane_keeping(sim, x, seeds)}
    sim.ego_policy = PilotNetEgo(net, sim.ego_policy)
    closed_loop["vision_pilotnet"] = _lane_keeping(sim, x, seeds)
    return closed_loop


def _file_entry(path: Path) -> dict[str, Any]:
    """A written file's size [bytes] and SHA-256, for the report."""
    return {
        "bytes": path.stat().st_size,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
    }


def train_vision(
    seed: int = 0,
    out_dir: str | Path = "vision",
    *,
    config: VisionTrainConfig | None = None,
    progress: Progress | None = None,
    threads: int | None = 1,
) -> dict[str, Any]:
    """Train PilotNet on rendered images of a scenario; write weights and report.

    Parameters
    ----------
    seed : int, default=0
        Seeds the network, the scenes and the shuffling.
    out_dir : str or Path, default="vision"
        Receives ``pilotnet.npz`` and ``training_report.json``.
    config : VisionTrainConfig, optional
        Default ``VisionTrainConfig()``, the settings of the shipped weights.
    progress : callable, optional
        Receives :class:`~avrisk.learning.train_config.TrainEvent` reports.
    threads : int or None, default=1
        torch CPU threads during the run (restored afterwards); one makes the
        run bit-reproducible on a machine.

    Returns
    -------
    dict
        The training report (also written as JSON).
    """
    config = VisionTrainConfig() if config is None else config
    previous = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        return _train_vision(seed, Path(out_dir), config, progress)
    finally:
        torch.set_num_threads(previous)


def _train_vision(
    seed: int, out: Path, config: VisionTrainConfig, progress: Progress | None
) -> dict[str, Any]:
    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(seed)
    spec = _with_lidar_ego(load_spec(config.scenario), config.horizon)
    sim = ScenarioSimulator(spec)
    base = base_distribution(spec)
    rng = np.random.default_rng(seed)

    def scenes(n: int) -> tuple[np.ndarray, np.ndarray]:
        return base.sample(n, rng), rng.integers(0, 2**62, size=n)

    def frames(n: int, learner: PilotNet | None, k: int) -> tuple[Tensor, Tensor]:
        return collect_frames(
            sim,
            *scenes(n),
            learner,
            config.frame_every,
            steer_noise=config.steer_noise,
            seed=seed * 1000 + k,
        )

    val_images, val_labels = frames(config.val_rollouts, None, 999)
    images, labels = frames(config.rollouts, None, 0)
    net = PilotNet(
        float(labels.mean()), float(labels.std(correction=0).clamp_min(1e-6))
    )
    optimizer = torch.optim.Adam(net.parameters(), lr=config.lr)
    gen = torch.Generator().manual_seed(seed)
    rounds = []
    for k in range(config.dagger_rounds + 1):
        if k > 0:
            new_images, new_labels = frames(config.rollouts, net, k)
            images = torch.cat([images, new_images])
            labels = torch.cat([labels, new_labels])
        loss = _fit(net, images, labels, config, gen, optimizer, progress, k)
        rounds.append(
            {
                "round": k,
                "frames": len(labels),
                "train_loss": loss,
                "val": _steering_error(net, val_images, val_labels),
            }
        )
    # What ships is the float16 file: evaluate that.
    weights = out / PILOTNET_FILE
    net.save(weights)
    net = PilotNet.load(weights)
    closed_loop = _closed_loop(sim, net, *scenes(config.eval_rollouts))
    report = {
        "seed": seed,
        "config": asdict(config),
        "rounds": rounds,
        "held_out_steering": _steering_error(net, val_images, val_labels),
        "closed_loop": closed_loop,
        "files": {PILOTNET_FILE: _file_entry(weights)},
        "environment": training_environment(),
        "seconds": round(time.perf_counter() - start, 1),
    }
    (out / REPORT_FILE).write_text(json.dumps(report, indent=1) + "\n")
    return report
