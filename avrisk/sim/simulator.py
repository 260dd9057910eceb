"""The batched highway simulator: initial states, driver parameters, seeds in; f out.

One call simulates ``B`` independent rollouts of ``A`` vehicles each, all as
tensors with a leading batch dimension. Per step ``t = 1..T`` (``T =
horizon / dt``):

1. every vehicle observes (lidar, lane features, flags; the full state as
   privileged information);
2. the driver model acts for every vehicle; an ego policy, if given, replaces
   the ego's (vehicle 0) action;
3. the kinematic bicycle advances every vehicle (:mod:`avrisk.sim.dynamics`);
4. the safety measure (ray TTC from the ego centre, :mod:`avrisk.safety.ttc`),
   collisions, road departure and reversing are evaluated.

The state at ``t = 0`` is measured too. A rollout *stops* at the first step at
which the ego's rectangle overlaps another vehicle's (a crash): its state
freezes there and its ``f`` is final, including that step's TTC. Collisions
between two environment vehicles do not stop a rollout (they show in the
observations' ``collided`` flag). Road departure and reversing are recorded for
the ego (the vehicle under test) and do not stop the rollout.

Reproducibility
---------------
A rollout's result depends only on its own initial state, parameters and
seed. Every operation is elementwise along the batch dimension or reduces over
vehicles and rays within one rollout (``min``/``max``, which are exact), and
every floating-point operation is one that IEEE 754 rounds correctly (``+ - *
/``, a correctly rounded square root, and trigonometry built from those in
:mod:`avrisk.tensors.mathops`). So results are bit-identical alone, in any batch,
in any order, in eager mode and under ``torch.compile``, and should be on any
device (float32; the tests check all but the device). The loop ends early once
every rollout of the batch has stopped; eager ray casting goes through large
batches in slices; neither changes any result.

Speed
-----
One CPU thread, six vehicles with 20-beam lidar each, 360 TTC rays, dt 0.1 s:
eager mode does about 35,000 scenario-steps per second at batch 1024 (20,000 at
64); ``compile=True`` (or ``AVRISK_COMPILE=1``) about 110,000 at 1024 (100,000
at 64), after a compilation of 10-60 s per new batch size.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import torch
from torch import Tensor

from avrisk.agents.idm import IDMDriver, IDMParams
from avrisk.agents.policy import Action, DriverModel, Policy, reads_lidar
from avrisk.safety.base import SafetyMeasure
from avrisk.safety.ttc import MinTTC
from avrisk.sim.collision import offroad, pairwise_overlap, reversing
from avrisk.sim.dynamics import BicycleLimits, bicycle_step
from avrisk.sim.lidar import LidarScan, beam_directions, lidar_scan
from avrisk.sim.observation import LaneFeatures, Observation, lane_features
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

__all__ = [
    "COMPILE_ENV",
    "RolloutResult",
    "SimConfig",
    "Simulator",
    "Trace",
    "compile_requested",
]

#: Environment variable that switches ``torch.compile`` on when ``Simulator``
#: is built with ``compile=None`` (the default).
COMPILE_ENV = "AVRISK_COMPILE"


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Parameters
    ----------
    dt : float, default=0.1
        Time step [s].
    horizon : float, default=10.0
        Simulated time [s]; ``T = ceil(horizon / dt)`` steps.
    n_lidar_beams : int, default=20
        Beams per vehicle lidar ``R``; 0 disables lidar.
    lidar_range : float, default=50.0
        Lidar range [m].
    n_ttc_rays : int, default=360
        Rays cast from the ego centre for the TTC ``N``.
    ttc_range : float, default=100.0
        Length of the TTC rays [m].
    accel_min, accel_max : float, default=-9.0, 6.0
        Physical acceleration limits [m/s^2].
    max_steer : float, default=0.6
        Physical front-wheel angle limit [rad].
    min_speed, max_speed : float, default=-10.0, 45.0
        Physical speed limits [m/s] (negative is reverse).
    wheelbase_fraction : float, default=0.6
        Wheelbase over vehicle length [-].
    """

    dt: float = 0.1  # [s]
    horizon: float = 10.0  # [s]
    n_lidar_beams: int = 20
    lidar_range: float = 50.0  # [m]
    n_ttc_rays: int = 360
    ttc_range: float = 100.0  # [m]
    accel_min: float = -9.0  # [m/s^2]
    accel_max: float = 6.0  # [m/s^2]
    max_steer: float = 0.6  # [rad]
    min_speed: float = -10.0  # [m/s]
    max_speed: float = 45.0  # [m/s]
    wheelbase_fraction: float = 0.6  # [-]

    def __post_init__(self) -> None:
        if not self.dt > 0:
            raise ValueError(f"dt must be > 0 [s]; got {self.dt}")
        if not self.horizon >= 0:
            raise ValueError(f"horizon must be >= 0 [s]; got {self.horizon}")
        if self.n_lidar_beams < 0:
            raise ValueError(f"n_lidar_beams must be >= 0; got {self.n_lidar_beams}")
        if not self.lidar_range > 0:
            raise ValueError(f"lidar_range must be > 0 [m]; got {self.lidar_range}")
        if self.n_ttc_rays < 1:
            raise ValueError(f"n_ttc_rays must be >= 1; got {self.n_ttc_rays}")
        if not self.ttc_range > 0:
            raise ValueError(f"ttc_range must be > 0 [m]; got {self.ttc_range}")
        self.limits  # noqa: B018  (validates the physical limits)

    @property
    def n_steps(self) -> int:
        """Number of steps ``T`` of a full rollout."""
        return math.ceil(self.horizon / self.dt - 1e-9)

    @property
    def limits(self) -> BicycleLimits:
        """The physical limits as the bicycle model takes them."""
        return BicycleLimits(
            accel_min=self.accel_min,
            accel_max=self.accel_max,
            max_steer=self.max_steer,
            min_speed=self.min_speed,
            max_speed=self.max_speed,
            wheelbase_fraction=self.wheelbase_fraction,
        )


@dataclass(frozen=True)
class Trace:
    """Recorded trajectories of a batch, for animation and inspection.

    Frame ``t`` is the state at time ``t * dt``; after a rollout stops, its
    frames repeat the stopping state and ``alive`` is false.

    Attributes
    ----------
    x, y, heading, speed : Tensor of shape (B, T+1, A)
        As in :class:`~avrisk.sim.state.VehicleState` [m, m, rad, m/s].
    alive : Tensor of bool, shape (B, T+1)
        ``alive[b, t]`` iff ``t <= steps[b]``: frame ``t`` was simulated.
    ttc : Tensor of shape (B, T+1)
        Instantaneous TTC at each frame [s]; ``inf`` where not alive.
    """

    x: Tensor  # [B, T+1, A] m
    y: Tensor  # [B, T+1, A] m
    heading: Tensor  # [B, T+1, A] rad
    speed: Tensor  # [B, T+1, A] m/s
    alive: Tensor  # [B, T+1] bool
    ttc: Tensor  # [B, T+1] s


@dataclass(frozen=True)
class RolloutResult:
    """Outcome of a batch of rollouts.

    Attributes
    ----------
    f : Tensor of shape (B,)
        Minimum TTC over rays and time [s]; ``inf`` if nothing ever approached.
    crash : Tensor of bool, shape (B,)
        The ego collided (the rollout stopped there).
    offroad : Tensor of bool, shape (B,)
        A corner of the ego was beyond a road edge at some simulated step.
    reversing : Tensor of bool, shape (B,)
        The ego moved against the road direction at some simulated step.
    steps : Tensor of int64, shape (B,)
        Steps simulated: the crash step, or ``T`` (0 if it starts in a crash).
    trace : Trace or None
        Trajectories, when requested.
    collision_with : Tensor of int64, shape (B,)
        Vehicle the ego crashed into (lowest index if several); -1 if none.
    """

    f: Tensor  # [B] s
    crash: Tensor  # [B] bool
    offroad: Tensor  # [B] bool
    reversing: Tensor  # [B] bool
    steps: Tensor  # [B] int64
    trace: Trace | None = None
    collision_with: Tensor | None = field(default=None)  # [B] int64


# Eager ray casting works through the batch in slices of about this many
# ray-box tests: the temporaries (64k floats, 256 KiB) then stay in the CPU
# cache and below glibc's mmap threshold, instead of being mapped, page-faulted
# and zeroed afresh by every operation, which makes it 3-4x faster at large
# batches. Results are the same: every operation is elementwise along the batch.
_EAGER_CHUNK_TESTS = 1 << 16


def _in_chunks(fn: Any, tests_per_rollout: Any) -> Any:
    """``fn(state, cos, sin)`` evaluated on batch slices and concatenated."""

    def chunked(state: VehicleState, cos: Tensor, sin: Tensor) -> Any:
        n = state.batch_size
        step = max(1, _EAGER_CHUNK_TESTS // max(1, tests_per_rollout(state.n_vehicles)))
        if n <= step:
            return fn(state, cos, sin)
        parts = [
            fn(state[i : i + step], cos[i : i + step], sin[i : i + step])
            for i in range(0, n, step)
        ]
        if isinstance(parts[0], Tensor):
            return torch.cat(parts)
        return type(parts[0]).cat(parts)

    return chunked


class _Geometry(NamedTuple):
    """What one state implies, short of ray casting (internal)."""

    cos: Tensor  # [B, A]
    sin: Tensor  # [B, A]
    overlap: Tensor  # [B, A, A] bool
    offroad: Tensor  # [B, A] bool
    reversing: Tensor  # [B, A] bool
    lane: LaneFeatures


def compile_requested(compile: bool | None) -> bool:
    """Whether a simulator compiles: ``compile``, or if None, ``AVRISK_COMPILE``.

    Parameters
    ----------
    compile : bool or None

    Returns
    -------
    bool
        ``compile`` when given; for None, whether the environment variable
        ``AVRISK_COMPILE`` is ``1``, ``true`` or ``yes``.
    """
    if compile is None:
        flag = os.environ.get(COMPILE_ENV, "0").strip().lower()
        return flag in ("1", "true", "yes")
    return bool(compile)


class Simulator:
    """Batched highway simulator (see the module docstring).

    Parameters
    ----------
    road : Road
        Straight road (``curvature == 0``).
    config : SimConfig, default=SimConfig()
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32
        Floating type of the simulation (float32 is the fast default; float64
        for checks).
    measure : SafetyMeasure or None
        Safety measure ``f``; default :class:`~avrisk.safety.ttc.MinTTC` with
        the config's rays.
    compile : bool or None, default=None
        Run each step through ``torch.compile`` (inductor; needs a C++
        compiler): about three times faster at large batches, after a one-off
        compilation of about a minute per new batch size (the first size gets
        fixed-shape kernels, later sizes share one dynamic-shape set; compiled
        code is cached on disk across runs). Results are the same as in eager
        mode, bit for bit. None reads the environment variable
        ``AVRISK_COMPILE`` (``1`` to compile), so that a command line or a
        benchmark can switch it on without code changes; default off.

    Examples
    --------
    >>> import torch
    >>> sim = Simulator(Road(n_lanes=3), SimConfig(horizon=1.0))
    >>> state = VehicleState.from_rows(
    ...     [[0.0, 1.85, 0.0, 20.0, 4.8, 1.9], [30.0, 1.85, 0.0, 15.0, 4.8, 1.9]]
    ... )
    >>> params = IDMParams.full((1, 2))
    >>> res = sim.rollout(state, params, torch.tensor([0]))
    >>> res.f.shape, bool(res.crash[0]), int(res.steps[0])
    (torch.Size([1]), False, 10)
    """

    def __init__(
        self,
        road: Road,
        config: SimConfig = SimConfig(),
        *,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
        measure: SafetyMeasure | None = None,
        compile: bool | None = None,
    ) -> None:
        if road.curvature != 0.0:
            raise NotImplementedError(
                f"only straight roads are simulated; got curvature={road.curvature} "
                "[1/m] (use 0.0)"
            )
        if not dtype.is_floating_point:
            raise ValueError(f"dtype must be floating; got {dtype}")
        self.road = road
        self.config = config
        self.device = torch.device(device)
        self.dtype = dtype
        self.limits = config.limits
        self.measure = measure or MinTTC(
            config.n_ttc_rays, config.ttc_range, dtype=dtype, device=self.device
        )
        self._beams = (
            beam_directions(config.n_lidar_beams, dtype=dtype, device=self.device)
            if config.n_lidar_beams > 0
            else None
        )
        self.compile = compile_requested(compile)
        self._compiled_acts: dict[type, Any] = {}
        self._move = self._move_impl
        per_pair, n_beams = self.measure.tests_per_pair, config.n_lidar_beams
        self._ttc = _in_chunks(self.measure.instant, lambda a: (a - 1) * per_pair)
        self._scan = _in_chunks(self._scan_impl, lambda a: a * (a - 1) * n_beams)
        if compile:
            # Three graphs per step plus the driver's (see _driver_act), each
            # small enough for inductor to compile in seconds. dynamic=None:
            # static shapes first, one dynamic-B graph after a batch-size change.
            self._move = torch.compile(self._move_impl)
            self._ttc = torch.compile(self.measure.instant)
            self._scan = torch.compile(self._scan_impl)

    # ------------------------------------------------------------------ public
    def rollout(
        self,
        initial: VehicleState,
        driver_params: IDMParams,
        seeds: Tensor,
        *,
        record_trace: bool = False,
        ego_policy: Policy | None = None,
    ) -> RolloutResult:
        """Simulate a batch with IDM+MOBIL drivers.

        Parameters
        ----------
        initial : VehicleState
            Fields of shape (B, A); vehicle 0 is the ego.
        driver_params : IDMParams
            Fields of shape (B, A): every vehicle's driver, the ego's included
            (the ego drives IDM+MOBIL unless ``ego_policy`` is given).
        seeds : Tensor of int64, shape (B,)
            Per-rollout seeds (counter-based noise of stochastic policies).
        record_trace : bool, default=False
            Also return the trajectories (memory ``O(B T A)``).
        ego_policy : Policy or None
            Drives the ego instead of its IDM+MOBIL driver.

        Returns
        -------
        RolloutResult
        """
        initial = self._prepare_state(initial)
        params = driver_params.to(self.device, self.dtype).validate()
        if params.shape != initial.shape:
            raise ValueError(
                f"driver_params have shape {tuple(params.shape)}, the initial state "
                f"{tuple(initial.shape)}; both must be (B, A)"
            )
        driver = IDMDriver(
            params, self.road, wheelbase_fraction=self.config.wheelbase_fraction
        )
        return self.run(
            initial, driver, seeds, ego_policy=ego_policy, record_trace=record_trace
        )

    def run(
        self,
        initial: VehicleState,
        driver: DriverModel,
        seeds: Tensor,
        *,
        ego_policy: Policy | None = None,
        record_trace: bool = False,
    ) -> RolloutResult:
        """Simulate a batch with any driver model (see :meth:`rollout`).

        Parameters
        ----------
        initial : VehicleState
            Fields of shape (B, A).
        driver : DriverModel
            Acts for every vehicle (the ego too, unless ``ego_policy``).
        seeds : Tensor of int64, shape (B,)
        ego_policy : Policy or None
        record_trace : bool, default=False

        Returns
        -------
        RolloutResult
        """
        state = self._prepare_state(initial)
        seeds = torch.as_tensor(seeds, device=self.device)
        if seeds.shape != (state.batch_size,) or seeds.dtype != torch.int64:
            raise ValueError(
                f"seeds must be int64 of shape ({state.batch_size},); got "
                f"{seeds.dtype} of shape {tuple(seeds.shape)}"
            )
        with torch.no_grad():
            return self._run(state, driver, seeds, ego_policy, record_trace)

    def observe(self, state: VehicleState, seeds: Tensor, step: int = 0) -> Observation:
        """The observation of a state, as policies receive it at ``step``.

        Parameters
        ----------
        state : VehicleState
            Fields of shape (B, A).
        seeds : Tensor of int64, shape (B,)
        step : int, default=0

        Returns
        -------
        Observation
        """
        state = self._prepare_state(state)
        with torch.no_grad():
            geo = self._geometry(state)
            return self._observation(state, geo, self._lidar(state, geo), seeds, step)

    # ---------------------------------------------------------------- internal
    def _prepare_state(self, state: VehicleState) -> VehicleState:
        return state.to(self.device, self.dtype).validate()

    def _geometry(self, state: VehicleState) -> _Geometry:
        cos, sin = state.cos_sin
        return _Geometry(
            cos=cos,
            sin=sin,
            overlap=pairwise_overlap(state, cos, sin),
            offroad=offroad(state, cos, sin, self.road),
            reversing=reversing(state, cos),
            lane=lane_features(state, self.road),
        )

    def _move_impl(
        self, state: VehicleState, accel: Tensor, steer: Tensor, alive: Tensor
    ) -> tuple[VehicleState, _Geometry]:
        """Advance the rollouts still ``alive`` by one step, and their geometry."""
        moved = bicycle_step(state, accel, steer, self.config.dt, self.limits)
        state = moved.where(alive, state)
        return state, self._geometry(state)

    def _scan_impl(self, state: VehicleState, cos: Tensor, sin: Tensor) -> LidarScan:
        assert self._beams is not None
        return lidar_scan(
            state, cos, sin, self.road, *self._beams, self.config.lidar_range
        )

    def _lidar(self, state: VehicleState, geo: _Geometry) -> LidarScan | None:
        return None if self._beams is None else self._scan(state, geo.cos, geo.sin)

    def _observation(
        self,
        state: VehicleState,
        geo: _Geometry,
        lidar: LidarScan | None,
        seeds: Tensor,
        step: int,
    ) -> Observation:
        return Observation(
            state=state,
            lidar=lidar,
            lane=geo.lane,
            collided=geo.overlap.any(dim=-1),
            offroad=geo.offroad,
            reversing=geo.reversing,
            seeds=seeds,
            step=step,
            dt=self.config.dt,
        )

    def _driver_act(self, driver: DriverModel) -> Any:
        """``driver.act``, compiled if the simulator compiles (one graph per class)."""
        if not self.compile:
            return driver.act
        cls = type(driver)
        if cls not in self._compiled_acts:
            self._compiled_acts[cls] = torch.compile(cls.act)
        compiled = self._compiled_acts[cls]
        return lambda obs, state: compiled(driver, obs, state)

    def _act(
        self,
        obs: Observation,
        act: Any,
        driver_state: Any,
        ego_policy: Policy | None,
        ego_state: Any,
    ) -> tuple[Action, Any, Any]:
        action, driver_state = act(obs, driver_state)
        if ego_policy is not None:
            ego, ego_state = ego_policy.act(obs, ego_state)
            accel = ego.accel.reshape(-1, 1).to(action.accel)
            steer = ego.steer.reshape(-1, 1).to(action.steer)
            action = Action(
                accel=torch.cat([accel, action.accel[:, 1:]], dim=1),
                steer=torch.cat([steer, action.steer[:, 1:]], dim=1),
            )
        return action, driver_state, ego_state

    def _run(
        self,
        state: VehicleState,
        driver: DriverModel,
        seeds: Tensor,
        ego_policy: Policy | None,
        record_trace: bool,
    ) -> RolloutResult:
        n_steps = self.config.n_steps
        measure = self.measure
        geo = self._geometry(state)
        ttc = self._ttc(state, geo.cos, geo.sin)
        ego_overlap = geo.overlap[:, 0, :]
        crash = ego_overlap.any(dim=-1)
        partner = torch.where(crash, ego_overlap.to(torch.int8).argmax(dim=-1), -1)
        carry = measure.init(ttc)
        off = geo.offroad[:, 0]
        rev = geo.reversing[:, 0]
        steps = torch.zeros_like(seeds)
        alive = ~crash

        # Scan lidar only if the drivers or the ego read it (results are the same).
        lidar_read = reads_lidar(driver) or (
            ego_policy is not None and reads_lidar(ego_policy)
        )

        def lidar(state: VehicleState, geo: _Geometry) -> LidarScan | None:
            return self._lidar(state, geo) if lidar_read else None

        obs = self._observation(state, geo, lidar(state, geo), seeds, 0)
        act = self._driver_act(driver)
        driver_state = driver.init(obs)
        ego_state = ego_policy.init(obs) if ego_policy is not None else None
        frames: list[tuple[Tensor, ...]] = []
        if record_trace:
            frames.append(self._frame(state, torch.ones_like(alive), ttc))

        for k in range(1, n_steps + 1):
            if not bool(alive.any()):
                break
            action, driver_state, ego_state = self._act(
                obs, act, driver_state, ego_policy, ego_state
            )
            state, geo = self._move(state, action.accel, action.steer, alive)
            ttc = self._ttc(state, geo.cos, geo.sin)
            carry = measure.update(carry, ttc, alive)
            ego_overlap = geo.overlap[:, 0, :]
            hit = alive & ego_overlap.any(dim=-1)
            partner = torch.where(
                hit, ego_overlap.to(torch.int8).argmax(dim=-1), partner
            )
            crash = crash | hit
            off = off | (alive & geo.offroad[:, 0])
            rev = rev | (alive & geo.reversing[:, 0])
            steps = torch.where(alive, k, steps)
            if record_trace:
                frames.append(self._frame(state, alive, ttc))
            alive = alive & ~hit
            if k < n_steps:
                obs = self._observation(state, geo, lidar(state, geo), seeds, k)

        trace = None
        if record_trace:
            while len(frames) < n_steps + 1:  # everyone stopped early
                x, y, heading, speed, live, t = frames[-1]
                frames.append(
                    (
                        x,
                        y,
                        heading,
                        speed,
                        torch.zeros_like(live),
                        torch.full_like(t, math.inf),
                    )
                )
            trace = Trace(
                *(torch.stack(parts, dim=1) for parts in zip(*frames, strict=True))
            )
        return RolloutResult(
            f=measure.finalize(carry),
            crash=crash,
            offroad=off,
            reversing=rev,
            steps=steps,
            trace=trace,
            collision_with=partner,
        )

    @staticmethod
    def _frame(state: VehicleState, alive: Tensor, ttc: Tensor) -> tuple[Tensor, ...]:
        return (
            state.x,
            state.y,
            state.heading,
            state.speed,
            alive,
            torch.where(alive, ttc, math.inf),
        )
