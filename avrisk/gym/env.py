"""The simulator as a Gymnasium environment: the agent drives the ego.

:class:`HighwayEnv` is one rollout, :class:`HighwayVectorEnv` ``B`` rollouts
in one batch of the simulator. Both step the scenario's simulator one ``dt``
at a time (:meth:`avrisk.assembly.ScenarioSimulator.start`) with the
scenario's drivers acting and the ego (vehicle 0) taking the agent's action:
the scenario's ego policy is replaced by :class:`HeldAction`, an ego policy
whose action is set from outside before each step.

Spaces
------
Observation: a flat ``Box`` (float32) of the ego's part of the simulator's
observation, the fields the external ego receives
(:data:`avrisk.agents.external.spaces.OBSERVATION_UNITS`, in that order): its
state (x, y, heading, speed, length, width), lane features (lane index,
offsets, marking and edge distances, curvature), flags (collided, offroad,
reversing; 0/1) and, when the scenario has a lidar, the ``R`` lidar ranges
[m] then the ``R`` range-rates [m/s] (:data:`OBSERVATION_FIELDS` gives the
layout). Action: a ``Box`` of (acceleration [m/s^2], steering [rad]) within
the simulator's physical limits (it clips to them as well).

Episodes
--------
``reset(seed=...)`` draws the scenario's ``X`` from ``P0``
(:func:`avrisk.assembly.base_distribution`) and the rollout's seed (the
drivers' noise) from the environment's generator; ``options={"x": x}`` gives
``X`` (shape (D,), the layout of :func:`avrisk.assembly.param_layout`),
``options={"proposal": q}`` draws it from another distribution (anything
with ``sample(n, rng)``, e.g. a fitted cross-entropy proposal). An episode
*terminates* when the ego crashes (the simulator stops the rollout there) or
when the action is not finite (``info["failed"]``), and is *truncated* at
the scenario's horizon.

Reward (a placeholder; RL users will replace it, e.g. with a wrapper reading
``info``): ``-1`` at the crash step, else the ego's progress along the road in
the step over ``max_speed * horizon`` (so at most about 1 per episode).

``info``: ``min_ttc`` (the scenario's safety measure ``f`` so far [s], the
quantity avrisk estimates the tail of), ``ttc`` (its instantaneous value),
``crash``, ``offroad``, ``reversing``, ``failed`` (bool) and ``t`` (steps).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from avrisk.agents.external.spaces import OBSERVATION_UNITS, observation_arrays
from avrisk.agents.policy import EgoActor
from avrisk.assembly import ScenarioSimulator, base_distribution
from avrisk.scenario import load_spec
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = [
    "OBSERVATION_FIELDS",
    "HeldAction",
    "HighwayEnv",
    "HighwayVectorEnv",
    "flat_observation",
    "observation_fields",
]

#: Per-field width of the flat observation without lidar (lidar fields: ``R``).
OBSERVATION_FIELDS = {n: 1 for n in OBSERVATION_UNITS if not n.startswith("lidar")}
_FLAGS = ("collided", "offroad", "reversing")


def observation_fields(n_lidar_beams: int) -> dict[str, int]:
    """Every field of the flat observation and its width, in order.

    Examples
    --------
    >>> fields = observation_fields(20)
    >>> list(fields)[:4], fields["lidar_range"], sum(fields.values())
    (['x', 'y', 'heading', 'speed'], 20, 57)
    """
    fields = dict(OBSERVATION_FIELDS)
    if n_lidar_beams > 0:
        fields.update(lidar_range=n_lidar_beams, lidar_range_rate=n_lidar_beams)
    return fields


def flat_observation(obs: Observation, n_lidar_beams: int) -> np.ndarray:
    """The ego's flat observation of a batch, (B, n) float32, as the env gives it.

    For running a policy trained in the environment as an ego policy
    (``avrisk run``): its ``act`` reads ``flat_observation(obs, R)``.
    """
    arrays = observation_arrays(obs)
    b = obs.state.x.shape[0]
    parts = [arrays[name].reshape(b, -1) for name in observation_fields(n_lidar_beams)]
    return np.concatenate(parts, axis=1).astype(np.float32)


class HeldAction:
    """An ego policy whose action is set from outside (the agent's).

    ``act`` returns :attr:`action` (fields of shape (B,)), set before each
    step. It reads the lidar so that the simulator scans it.
    """

    reads_lidar = True

    def __init__(self) -> None:
        self.action: Action | None = None

    def init(self, obs: Observation) -> None:
        """No memory."""
        return None

    def act(self, obs: Observation, state: None) -> tuple[Action, None]:
        """The held action."""
        if self.action is None:
            raise RuntimeError("no action set before the step")
        return self.action, None


class _Batch:
    """``B`` rollouts of a scenario stepped by hand, ego driven from outside."""

    def __init__(
        self, scenario: str | Path | ScenarioSpec, device: str | torch.device
    ) -> None:
        spec = scenario if isinstance(scenario, ScenarioSpec) else load_spec(scenario)
        self.sim = ScenarioSimulator(spec, device=device)
        self.held = HeldAction()
        # The agent replaces the scenario's ego (it controls slot 0, last).
        self.sim.ego_policy = EgoActor(
            self.held, spec.n_vehicles, device=self.sim.device
        )
        self.p0 = base_distribution(spec)
        config = self.sim.config
        self.n_steps = config.n_steps
        self.fields = observation_fields(config.n_lidar_beams)
        low, high = [], []
        for name, width in self.fields.items():
            lo, hi = -math.inf, math.inf
            if name in _FLAGS:
                lo, hi = 0.0, 1.0
            elif name == "lane":
                lo, hi = 0.0, float(spec.road.n_lanes - 1)
            elif name in ("length", "width", "lidar_range"):
                lo = 0.0
            low += [lo] * width
            high += [hi] * width
        self.observation_space = spaces.Box(
            np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)
        )
        self.action_space = spaces.Box(
            np.array([config.accel_min, -config.max_steer], dtype=np.float32),
            np.array([config.accel_max, config.max_steer], dtype=np.float32),
        )
        self.progress_scale = 1.0 / (config.max_speed * config.horizon)

    def draw(
        self, n: int, rng: np.random.Generator, options: dict[str, Any] | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``X`` (n, D) and seeds (n,) for a reset."""
        options = options or {}
        x_rng, seed_rng = rng.spawn(2)
        if "x" in options:
            x = np.asarray(options["x"], dtype=np.float64).reshape(n, self.p0.dim)
        else:
            x = options.get("proposal", self.p0).sample(n, x_rng)
        seeds = seed_rng.integers(0, 2**62, size=n, dtype=np.int64)
        return x, seeds

    def start(self, x: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """Start the batch; the observations (B, n)."""
        self.x, self.seeds = x, seeds
        with torch.no_grad():
            self.carry, self._step = self.sim.start(x, seeds)
        self.t = 0
        self.done = (~self.carry.alive).cpu().numpy()
        return self.observe()

    def observe(self) -> np.ndarray:
        """The ego's flat observation of the carried state, (B, n) float32."""
        obs = self.sim.simulator.observe(
            self.carry.state, torch.as_tensor(self.seeds), self.t
        )
        return flat_observation(obs, self.sim.config.n_lidar_beams)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        """One step; observations, rewards, terminated, truncated, info arrays."""
        actions = np.asarray(actions, dtype=np.float32).reshape(-1, 2)
        act = torch.as_tensor(actions, device=self.sim.device)
        self.held.action = Action(accel=act[:, 0], steer=act[:, 1])
        was_alive = self.carry.alive
        x_before = self.carry.state.x[:, 0]
        with torch.no_grad():
            self.carry, ttc = self._step(self.carry, self.t)
        self.held.action = None
        self.t += 1
        c = self.carry
        progress = (c.state.x[:, 0] - x_before) * self.progress_scale
        hit = (was_alive & c.crash & ~c.alive).cpu().numpy()
        failed = (c.status != 0).cpu().numpy()
        reward = np.where(hit, -1.0, progress.cpu().numpy()).astype(np.float64)
        reward = np.where(failed, 0.0, reward)
        terminated = c.crash.cpu().numpy() | failed
        truncated = np.full_like(terminated, self.t >= self.n_steps) & ~terminated
        info = {
            "min_ttc": self.sim.simulator.measure.finalize(c.measure)
            .cpu()
            .numpy()
            .astype(np.float64),
            "ttc": ttc.cpu().numpy().astype(np.float64),
            "crash": c.crash.cpu().numpy(),
            "offroad": c.offroad.cpu().numpy(),
            "reversing": c.reversing.cpu().numpy(),
            "failed": failed,
            "t": np.full(len(self.seeds), self.t, dtype=np.int64),
        }
        return self.observe(), reward, terminated, truncated, info

    def info_at_start(self) -> dict[str, np.ndarray]:
        """``info`` of a reset: the measure at ``t = 0``."""
        c = self.carry
        f = self.sim.simulator.measure.finalize(c.measure)
        return {
            "min_ttc": f.cpu().numpy().astype(np.float64),
            "crash": c.crash.cpu().numpy(),
            "x": self.x,
            "seed": self.seeds,
        }


class HighwayEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """One rollout of a scenario, the agent driving the ego (module docstring).

    Parameters
    ----------
    scenario : str, pathlib.Path or ScenarioSpec, default="highway_idm"
        A bundled scenario's name, a YAML file or a spec.
    device : str or torch.device, default="cpu"
    render_mode : None
        No rendering (``avrisk report`` animates a run's failures).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        scenario: str | Path | ScenarioSpec = "highway_idm",
        *,
        device: str | torch.device = "cpu",
        render_mode: str | None = None,
    ) -> None:
        self._batch = _Batch(scenario, device)
        self.observation_space = self._batch.observation_space
        self.action_space = self._batch.action_space
        self.render_mode = render_mode
        self._done = True

    @property
    def scenario(self) -> ScenarioSimulator:
        """The scenario's simulator (its ``spec``, ``layout``, ``config``)."""
        return self._batch.sim

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw ``X`` (or take ``options["x"]``) and start a rollout."""
        super().reset(seed=seed)
        x, seeds = self._batch.draw(1, self.np_random, options)
        obs = self._batch.start(x, seeds)
        self._done = False
        return obs[0], _row(self._batch.info_at_start(), 0)

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Advance one ``dt`` with the ego taking ``action``."""
        if self._done:
            raise RuntimeError("call reset() first (the episode has ended)")
        obs, reward, term, trunc, info = self._batch.step(action)
        self._done = bool(term[0] or trunc[0])
        return obs[0], float(reward[0]), bool(term[0]), bool(trunc[0]), _row(info, 0)


class HighwayVectorEnv(VectorEnv):
    """``num_envs`` rollouts of a scenario in one batch of the simulator.

    The rollouts run in lockstep, one simulator call per step
    (``autoreset_mode`` DISABLED): a rollout that terminates (crash) stays
    frozen, and further steps report it terminated with reward 0, until
    :meth:`reset` starts a new batch (every rollout; the horizon truncates
    all of them at the same step). Rewards and ``info`` are as for
    :class:`HighwayEnv`, as arrays of shape (num_envs,).

    Parameters
    ----------
    num_envs : int, default=1
    scenario : str, pathlib.Path or ScenarioSpec, default="highway_idm"
    device : str or torch.device, default="cpu"
    """

    metadata: dict[str, Any] = {
        "render_modes": [],
        "autoreset_mode": AutoresetMode.DISABLED,
    }

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | Path | ScenarioSpec = "highway_idm",
        *,
        device: str | torch.device = "cpu",
        render_mode: str | None = None,
    ) -> None:
        self._batch = _Batch(scenario, device)
        self.num_envs = num_envs
        self.single_observation_space = self._batch.observation_space
        self.single_action_space = self._batch.action_space
        self.observation_space = gymnasium.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gymnasium.vector.utils.batch_space(
            self.single_action_space, num_envs
        )
        self.render_mode = render_mode
        self._ended = np.ones(num_envs, dtype=bool)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw ``X`` for every rollout (or take ``options["x"]``, (B, D))."""
        if isinstance(seed, list):
            raise ValueError("give one seed for the batch (or None)")
        super().reset(seed=seed)
        x, seeds = self._batch.draw(self.num_envs, self.np_random, options)
        obs = self._batch.start(x, seeds)
        self._ended = np.zeros(self.num_envs, dtype=bool)
        return obs, self._batch.info_at_start()

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Advance every rollout one ``dt``; actions of shape (num_envs, 2)."""
        obs, reward, term, trunc, info = self._batch.step(actions)
        reward = np.where(self._ended, 0.0, reward)
        self._ended = self._ended | term | trunc
        return obs, reward, term, trunc, info


def _row(info: dict[str, np.ndarray], i: int) -> dict[str, Any]:
    """Row ``i`` of batched ``info`` arrays, as Python scalars or arrays."""
    out: dict[str, Any] = {}
    for k, v in info.items():
        item = v[i]
        out[k] = item.item() if np.ndim(item) == 0 else item
    return out
