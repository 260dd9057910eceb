"""The simulator as a Gymnasium environment: the agent drives the ego.

:class:`HighwayEnv` is one rollout, :class:`HighwayVectorEnv` ``B`` rollouts
in one batch of the simulator, each restarted on its own when its episode
ends (Gymnasium's next-step autoreset). Both step the scenario's simulator one ``dt``
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

``info`` (the same keys at reset and at every step): ``min_ttc`` (the
scenario's safety measure ``f`` so far [s], the quantity avrisk estimates the
tail of), ``ttc`` (its instantaneous value [s]), ``crash``, ``offroad``,
``reversing``, ``failed`` (bool), ``t`` (steps), and the episode's ``x``
(shape (D,)) and ``seed`` (the drivers' noise): ``avrisk`` replays the episode
from them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv

from avrisk.agents.external.spaces import OBSERVATION_UNITS, observation_arrays
from avrisk.agents.policy import EgoActor
from avrisk.assembly import ScenarioSimulator, base_distribution
from avrisk.scenario import load_spec
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation
from avrisk.sim.state import VehicleState

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
        self,
        rng: np.random.Generator,
        proposal: Any | None = None,
        x: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``X`` (1, D) and the seed (1,) of one rollout, from its generator.

        ``x`` (D,) when given, else a draw from ``proposal`` (``P0`` if None).
        """
        x_rng, seed_rng = rng.spawn(2)
        if x is not None:
            x = np.asarray(x, dtype=np.float64).reshape(1, self.p0.dim)
        else:
            x = (self.p0 if proposal is None else proposal).sample(1, x_rng)
        seeds = seed_rng.integers(0, 2**62, size=1, dtype=np.int64)
        return x, seeds

    def start(self, x: np.ndarray, seeds: np.ndarray) -> None:
        """Start the batch from ``X`` (B, D) and seeds (B,)."""
        self.x, self.seeds = x, seeds
        with torch.no_grad():
            self.carry, self._step = self.sim.start(x, seeds)
        self.t = np.zeros(len(seeds), dtype=np.int64)
        self.ttc = self._ttc_now(self.carry.state)

    def restart(self, rows: np.ndarray, x: np.ndarray, seeds: np.ndarray) -> None:
        """Start the rollouts where ``rows`` (B,) is true anew; the others go on."""
        rows_t = torch.as_tensor(rows, device=self.sim.device)
        with torch.no_grad():
            self.carry = self.sim.restart(self.carry, rows_t, x, seeds)
        self.x, self.seeds = self.x.copy(), self.seeds.copy()
        self.x[rows], self.seeds[rows], self.t[rows] = x, seeds, 0
        ttc = self.ttc.clone()
        ttc[rows_t] = self._ttc_now(self.carry.state[rows_t])
        self.ttc = ttc

    def _ttc_now(self, state: VehicleState) -> torch.Tensor:
        """The measure's instantaneous value of a state (n,) [s], as at ``t = 0``."""
        with torch.no_grad():
            return self.sim.simulator.measure.instant(state)

    def observe(self) -> np.ndarray:
        """The ego's flat observation of the carried state, (B, n) float32."""
        obs = self.sim.simulator.observe(
            self.carry.state, self._on_device(self.seeds), self._on_device(self.t)
        )
        return flat_observation(obs, self.sim.config.n_lidar_beams)

    def _on_device(self, per_row: np.ndarray) -> torch.Tensor:
        """Rollouts' seeds or step indices (B,), int64 on the simulator's device."""
        return torch.as_tensor(per_row, device=self.sim.device)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        """Every rollout one step on; rewards, terminated and truncated (B,)."""
        actions = np.asarray(actions, dtype=np.float32).reshape(-1, 2)
        act = torch.as_tensor(actions, device=self.sim.device)
        self.held.action = Action(accel=act[:, 0], steer=act[:, 1])
        was_alive = self.carry.alive
        x_before = self.carry.state.x[:, 0]
        seeds, t = self._on_device(self.seeds), self._on_device(self.t)
        try:
            with torch.no_grad():
                self.carry, self.ttc = self._step(self.carry, t, seeds=seeds)
        finally:
            self.held.action = None
        self.t = self.t + 1
        c = self.carry
        progress = (c.state.x[:, 0] - x_before) * self.progress_scale
        hit = (was_alive & c.crash & ~c.alive).cpu().numpy()
        failed = (c.status != 0).cpu().numpy()
        reward = np.where(hit, -1.0, progress.cpu().numpy()).astype(np.float64)
        reward = np.where(failed, 0.0, reward)
        terminated = c.crash.cpu().numpy() | failed
        truncated = (self.t >= self.n_steps) & ~terminated
        return reward, terminated, truncated

    def info(self) -> dict[str, np.ndarray]:
        """``info`` of every rollout as it stands, arrays with B rows."""
        c = self.carry
        f = self.sim.simulator.measure.finalize(c.measure)
        return {
            "min_ttc": f.cpu().numpy().astype(np.float64),
            "ttc": self.ttc.cpu().numpy().astype(np.float64),
            "crash": c.crash.cpu().numpy(),
            "offroad": c.offroad.cpu().numpy(),
            "reversing": c.reversing.cpu().numpy(),
            "failed": (c.status != 0).cpu().numpy(),
            "t": self.t.copy(),
            "x": self.x.copy(),
            "seed": self.seeds.copy(),
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
        options = options or {}
        x, seeds = self._batch.draw(
            self.np_random, options.get("proposal"), options.get("x")
        )
        self._batch.start(x, seeds)
        self._done = False
        return self._batch.observe()[0], _row(self._batch.info(), 0)

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Advance one ``dt`` with the ego taking ``action``."""
        if self._done:
            raise RuntimeError("call reset() first (the episode has ended)")
        reward, term, trunc = self._batch.step(action)
        self._done = bool(term[0] or trunc[0])
        obs, info = self._batch.observe()[0], _row(self._batch.info(), 0)
        return obs, float(reward[0]), bool(term[0]), bool(trunc[0]), info


class HighwayVectorEnv(VectorEnv):
    """``num_envs`` rollouts of a scenario in one batch of the simulator.

    Each sub-environment ``i`` behaves as a :class:`HighwayEnv` of its own
    (bit for bit: same seed, same actions, same observations, rewards and
    crash step), while one simulator call steps them all. Autoreset is
    Gymnasium's next-step mode (``metadata["autoreset_mode"]``
    ``NEXT_STEP``, as :class:`gymnasium.vector.SyncVectorEnv`): the step after
    a sub-environment terminates or truncates starts its next episode (its
    action is ignored; reward 0, not terminated, not truncated, the new
    episode's first observation and ``info``), while the others go on.

    Seeds: ``reset(seed=s)`` seeds sub-environment ``i`` with ``s + i``,
    ``reset(seed=[s_0, ...])`` with ``s_i`` (None: keep its generator); each
    draws its episodes' ``X`` and rollout seeds from its own generator, so
    sub-environment ``i`` gives the episodes a :class:`HighwayEnv` reset with
    ``seed=s_i`` and then reset without a seed would give.
    ``options={"x": x}`` gives the first episodes' ``X`` (shape (num_envs,
    D)); ``options={"proposal": q}`` draws them, and the autoreset episodes
    after them, from ``q`` instead of ``P0``.

    Rewards, ``terminated`` and ``truncated`` are arrays of shape
    (num_envs,); ``info`` has the keys of :class:`HighwayEnv` as arrays with
    num_envs rows, and Gymnasium's ``"_key"`` masks (every sub-environment
    has every key).

    Parameters
    ----------
    num_envs : int, default=1
    scenario : str, pathlib.Path or ScenarioSpec, default="highway_idm"
    device : str or torch.device, default="cpu"
    render_mode : None
    """

    metadata: dict[str, Any] = {
        "render_modes": [],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
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
        self._rngs: list[np.random.Generator | None] = [None] * num_envs
        self._proposal: Any | None = None
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._started = False

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode in every sub-environment (class docstring)."""
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(
                f"give one seed per sub-environment ({self.num_envs}); got {len(seeds)}"
            )
        for i, s in enumerate(seeds):
            if s is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(s)[0]
        options = options or {}
        self._proposal = options.get("proposal")
        given = options.get("x")
        if given is not None:
            given = np.asarray(given, dtype=np.float64).reshape(self.num_envs, -1)
        rows = np.arange(self.num_envs)
        x, rollout_seeds = self._draw(rows, given)
        self._batch.start(x, rollout_seeds)
        self._autoreset[:] = False
        self._started = True
        return self._batch.observe(), self._vector_info()

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Advance every sub-environment one ``dt``; actions (num_envs, 2).

        Sub-environments whose episode ended at the previous step start their
        next one instead (their actions are ignored).
        """
        if not self._started:
            raise RuntimeError("call reset() first")
        reward, terminated, truncated = self._batch.step(actions)
        restart = self._autoreset.copy()
        if restart.any():
            x, rollout_seeds = self._draw(np.flatnonzero(restart), None)
            self._batch.restart(restart, x, rollout_seeds)
            reward[restart] = 0.0
            terminated[restart] = truncated[restart] = False
        self._autoreset = terminated | truncated
        return self._batch.observe(), reward, terminated, truncated, self._vector_info()

    def _draw(
        self, rows: np.ndarray, given: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``X`` (n, D) and seeds (n,) of new episodes, each from its generator."""
        draws = []
        for k, i in enumerate(rows):
            rng = self._rngs[i]
            assert rng is not None
            x_i = None if given is None else given[k]
            draws.append(self._batch.draw(rng, self._proposal, x_i))
        x, seeds = zip(*draws, strict=True)
        return np.concatenate(x), np.concatenate(seeds)

    def _vector_info(self) -> dict[str, Any]:
        """The batch's ``info`` with Gymnasium's ``_key`` masks (all true)."""
        info: dict[str, Any] = self._batch.info()
        present = np.ones(self.num_envs, dtype=bool)
        info.update({f"_{k}": present.copy() for k in list(info)})
        return info


def _row(info: dict[str, np.ndarray], i: int) -> dict[str, Any]:
    """Row ``i`` of batched ``info`` arrays, as Python scalars or arrays."""
    out: dict[str, Any] = {}
    for k, v in info.items():
        item = v[i]
        out[k] = item.item() if np.ndim(item) == 0 else item
    return out
