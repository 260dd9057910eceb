"""The batched highway simulator: initial states, actors, seeds in; f out.

One call simulates ``B`` independent rollouts of ``A`` vehicles each, all as
tensors with a leading batch dimension. Per step ``t = 1..T`` (``T =
horizon / dt``):

1. every vehicle observes (lidar, lane features, flags; the full state as
   privileged information; the ego's camera image when an actor reads it);
2. the actors act (:mod:`avrisk.sim.interfaces`): each computes actions for
   the batch and the simulator keeps, per vehicle, the action of the last
   actor that controls it;
3. the kinematic bicycle advances every vehicle (:mod:`avrisk.sim.dynamics`);
4. the safety measure (:class:`~avrisk.sim.interfaces.SafetyMeasure`),
   collisions, road departure and reversing are evaluated.

The state at ``t = 0`` is measured too. A rollout *stops* at the first step at
which the ego's rectangle overlaps another vehicle's (a crash): its state
freezes there and its ``f`` is final, including that step's value. It stops
as well, before moving, when an actor returns a non-finite action for it (the
actor failed): it is marked failed (``status``) and its ``f`` is NaN.
Collisions between two environment vehicles do not stop a rollout (they show
in the observations' ``collided`` flag). Road departure and reversing are
recorded for the ego (the vehicle under test) and do not stop the rollout.

The step
--------
:meth:`Simulator.step` is one step as a pure function of tensors: carry
(:class:`RolloutCarry`: state, the actors' states, the measure's carry, the
flags) and step index in, the next carry and the step's TTC out, with no host
synchronisation and no Python loop over vehicles or rollouts. :meth:`run`
loops over it (:meth:`start`, ``step`` ``T`` times) and stops early once every
rollout has stopped: one host synchronisation per step, outside the step.
``compile=True`` runs the step through ``torch.compile(fullgraph=True)``: the
actors (driver network, IDM+MOBIL, the ego), lidar, features, collision and
TTC become one graph. The step also runs under autograd (gradients reach the
initial state and the actors' floating parameters, e.g. the drivers' ``xi``);
:meth:`run` switches gradients off.

Reproducibility
---------------
A rollout's result depends only on its own initial state, actor parameters
and seed. Every operation of the simulator is elementwise along the batch
dimension or reduces over vehicles and rays within one rollout (``min``/``max``,
which are exact), and every floating-point operation is one that IEEE 754
rounds correctly (``+ - * /``, a correctly rounded square root, and
trigonometry built from those in :mod:`avrisk.tensors.mathops`); the actors'
noise is counter-based (:mod:`avrisk.tensors.noise`). The one exception is the
learned drivers' matrix products, where BLAS picks its kernel by the number of
rows: :func:`avrisk.agents.drivers.network.row_linear` pads the rows to a
multiple of 16 so that every row takes the same kernel, and the per-rollout
last layer is a batched product per rollout (``bmm``). So results are
bit-identical alone, in any batch, in any order, in eager mode and under
``torch.compile`` (inductor calls the same BLAS for the products; the tests
check both bundled scenarios), on one machine, in float32. The vision ego is
the exception to the compiled half: its PilotNet convolutions round
differently under inductor than in eager mode (BENCHMARKS.md, "The vision
ego"), so its compiled rollouts match eager ones only to a tolerance; alone,
in any batch and in any order they stay bit-identical. On another device
(a GPU) or another BLAS the matrix products may round differently in the last
bit; elementwise work is the same. The loop ends early once every rollout of
the batch has stopped; eager ray casting goes through large batches in slices;
neither changes any result.

Speed
-----
``highway_default`` (six vehicles, learned drivers and ego with 20-beam lidar,
box TTC, dt 0.1 s), one CPU thread, on a shared two-core machine (BENCHMARKS.md,
"Simulator throughput", has the figures and commands): eager about 900 tensor
operations per step at small batches (the ray casting repeats per batch slice
at large ones); ``compile=True`` (or ``AVRISK_COMPILE=1``) about three times
the eager throughput at batch 1024, bit-identical, after a compilation of
about a minute per new batch size (more on a loaded machine; cached on disk
across runs, though tracing and loading still take about 10 s per process).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, NamedTuple

import torch
from torch import Tensor

from avrisk.sim.camera import Camera, CameraFrame, reads_camera
from avrisk.sim.collision import Contact, contact, offroad, pairwise_overlap, reversing
from avrisk.sim.dynamics import BicycleLimits, bicycle_step
from avrisk.sim.interfaces import Actor, NoiseRequest, SafetyMeasure, reads_lidar
from avrisk.sim.lidar import LidarScan, beam_directions, lidar_scan
from avrisk.sim.observation import LaneFeatures, Observation, lane_features
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.noise import normal
from avrisk.tensors.rows import replace_rows
from avrisk.tensors.slices import in_slices

__all__ = [
    "COMPILE_ENV",
    "RolloutCarry",
    "RolloutResult",
    "SimConfig",
    "Simulator",
    "Status",
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


class Status(IntEnum):
    """Per-rollout status codes (``RolloutResult.status``, int8)."""

    #: Simulated to its crash or to the horizon.
    OK = 0
    #: An actor returned a non-finite action for it: stopped there, ``f`` NaN.
    ACTOR_FAILED = 1


@dataclass(frozen=True)
class RolloutResult:
    """Outcome of a batch of rollouts.

    Attributes
    ----------
    f : Tensor of shape (B,)
        The safety measure, e.g. minimum TTC over time [s]; ``inf`` if nothing
        ever approached; NaN where ``status`` is not ``OK``.
    crash : Tensor of bool, shape (B,)
        The ego collided (the rollout stopped there).
    offroad : Tensor of bool, shape (B,)
        A corner of the ego was beyond a road edge at some simulated step.
    reversing : Tensor of bool, shape (B,)
        The ego moved against the road direction at some simulated step.
    steps : Tensor of int64, shape (B,)
        Steps simulated: the crash step, the last step before an actor
        failed, or ``T`` (0 if it starts in a crash).
    status : Tensor of int8, shape (B,)
        :class:`Status` code: 0 ok, 1 an actor failed for this rollout.
    collision_with : Tensor of int64, shape (B,)
        Vehicle the ego crashed into (lowest index if several); -1 if none.
    contact : Tensor of int8, shape (B,)
        :class:`~avrisk.sim.collision.Contact` mechanism of the crash, from
        the relative position at the crash step: 0 none, 1 the ego rear-ends
        the vehicle ahead in its lane-width band, 2 hit from behind, 3 side
        contact.
    trace : Trace or None
        Trajectories, when requested.
    """

    f: Tensor  # [B] s
    crash: Tensor  # [B] bool
    offroad: Tensor  # [B] bool
    reversing: Tensor  # [B] bool
    steps: Tensor  # [B] int64
    status: Tensor  # [B] int8
    collision_with: Tensor  # [B] int64
    contact: Tensor  # [B] int8
    trace: Trace | None = None


# Eager ray casting on a CPU works through the batch in slices of about this
# many ray-box tests (avrisk.tensors.slices): the temporaries (128k floats,
# 512 KiB) then stay in the CPU's L2 cache and below glibc's mmap threshold,
# instead of being mapped, page-faulted and zeroed afresh by every operation,
# which makes it 3-4x faster at large batches (2**17 scans 12% faster than
# 2**16, 2**18 50% slower, on an AMD EPYC with 512 KiB of L2 per core).
# Results are the same: every operation is elementwise along the batch.
_EAGER_CHUNK_TESTS = 1 << 17


def _in_chunks(fn: Any, tests_per_rollout: Any) -> Any:
    """``fn(state, cos, sin)`` evaluated on batch slices and concatenated."""

    def chunked(state: VehicleState, cos: Tensor, sin: Tensor) -> Any:
        per_rollout = tests_per_rollout(state.n_vehicles)
        args = (state, cos, sin)
        return in_slices(fn, args, per_rollout, _EAGER_CHUNK_TESTS, cos.device)

    return chunked


class _Geometry(NamedTuple):
    """What one state implies, short of ray casting (internal)."""

    cos: Tensor  # [B, A]
    sin: Tensor  # [B, A]
    overlap: Tensor  # [B, A, A] bool
    offroad: Tensor  # [B, A] bool
    reversing: Tensor  # [B, A] bool
    lane: LaneFeatures


class RolloutCarry(NamedTuple):
    """What a batch of rollouts carries from one step to the next.

    The input and output of :meth:`Simulator.step`: tensors (and the actors'
    states) only, so that the step is a pure function.

    Attributes
    ----------
    state : VehicleState
        Fields of shape (B, A), frozen where the rollout stopped.
    geo : tuple of Tensor
        What ``state`` implies short of ray casting (headings' cosines and
        sines (B, A), pairwise overlap (B, A, A), road departure and reversing
        flags (B, A), lane features (B, A)).
    actors : tuple
        Each actor's state, in the order of the actors.
    measure : Tensor of shape (B,)
        The safety measure's carry.
    alive : Tensor of bool, shape (B,)
        Still simulated (no crash, no actor failure).
    crash, offroad, reversing : Tensor of bool, shape (B,)
        As in :class:`RolloutResult`, so far.
    steps : Tensor of int64, shape (B,)
        Steps simulated so far.
    status : Tensor of int8, shape (B,)
    partner : Tensor of int64, shape (B,)
        ``collision_with`` so far (-1: none).
    contact : Tensor of int8, shape (B,)
    """

    state: VehicleState
    geo: _Geometry
    actors: tuple[Any, ...]
    measure: Tensor  # [B]
    alive: Tensor  # [B] bool
    crash: Tensor  # [B] bool
    offroad: Tensor  # [B] bool
    reversing: Tensor  # [B] bool
    steps: Tensor  # [B] int64
    status: Tensor  # [B] int8
    partner: Tensor  # [B] int64
    contact: Tensor  # [B] int8

    def with_rows(self, rows: Tensor, fresh: RolloutCarry) -> RolloutCarry:
        """The carry with some rollouts restarted, the others untouched.

        Parameters
        ----------
        rows : Tensor of bool, shape (B,)
            The rollouts to restart; ``n`` of them are true.
        fresh : RolloutCarry
            ``n`` rollouts at ``t = 0`` (:meth:`Simulator.start`), in the order
            of ``rows``, from the same actors' ``init``. Their steps count from
            0 again: step the batch with a step index per rollout
            (:meth:`Simulator.step` takes ``t`` of shape (B,)).

        Returns
        -------
        RolloutCarry

        Raises
        ------
        ValueError
            If an actor's state has a tensor that is neither per rollout
            (leading dimension ``B``) nor the same for every rollout.
        """
        return replace_rows(self, rows, fresh)


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
    measure : SafetyMeasure
        Safety measure ``f`` (:mod:`avrisk.safety` implements some).
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32
        Floating type of the simulation (float32 is the fast default; float64
        for checks).
    camera : Camera or None, default=None
        The ego's camera (:mod:`avrisk.sim.camera`; :mod:`avrisk.render`
        implements one), rendered at every step only when an actor reads it
        (``reads_camera = True``); None for a simulator without one.
    compile : bool or None, default=None
        Run each step through ``torch.compile(fullgraph=True)`` (inductor;
        needs a C++ compiler): one graph per step, actors included, about
        three times faster than eager at large batches, after a one-off
        compilation of about a minute per new batch size (the first size gets
        fixed-shape kernels, later sizes share one dynamic-shape set;
        compiled code is cached on disk across runs). Results are the same as
        in eager mode, bit for bit. None reads the environment variable
        ``AVRISK_COMPILE`` (``1`` to compile), so that a command line or a
        benchmark can switch it on without code changes; default off.

    Examples
    --------
    >>> import torch
    >>> from avrisk.safety import MinTTC
    >>> from avrisk.sim.interfaces import Action
    >>> class Cruise:  # an actor: every vehicle holds its speed
    ...     controlled = torch.tensor([True, True])
    ...     reads_lidar, noise = False, None
    ...     def init(self, obs, params):
    ...         return None
    ...     def act(self, obs, state, noise):
    ...         zero = torch.zeros_like(obs.state.x)
    ...         return Action(accel=zero, steer=zero), None
    >>> sim = Simulator(Road(n_lanes=3), SimConfig(horizon=1.0), measure=MinTTC())
    >>> state = VehicleState.from_rows(
    ...     [[0.0, 1.85, 0.0, 20.0, 4.8, 1.9], [30.0, 1.85, 0.0, 15.0, 4.8, 1.9]]
    ... )
    >>> res = sim.run(state, [Cruise()], torch.tensor([0]))
    >>> round(res.f.item(), 3), bool(res.crash[0]), int(res.steps[0])
    (4.52, False, 10)

    At 1 s the lead's rear is 22.6 m from the ego's centre, closing at 5 m/s.
    """

    def __init__(
        self,
        road: Road,
        config: SimConfig = SimConfig(),
        *,
        measure: SafetyMeasure,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
        camera: Camera | None = None,
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
        self.measure = measure
        self.camera = camera
        self._beams = (
            beam_directions(config.n_lidar_beams, dtype=dtype, device=self.device)
            if config.n_lidar_beams > 0
            else None
        )
        self.compile = compile_requested(compile)
        per_pair = measure.tests_per_pair
        self._ttc = _in_chunks(measure.instant, lambda a: (a - 1) * per_pair)
        # The whole step, actors included, as one graph (see step); dynamic=None:
        # static shapes first, one dynamic-B graph after a batch-size change.
        self._step = (
            torch.compile(self.step, fullgraph=True) if self.compile else self.step
        )

    # ------------------------------------------------------------------ public
    def run(
        self,
        initial: VehicleState,
        actors: Sequence[Actor],
        seeds: Tensor,
        *,
        params: Sequence[Tensor | None] | None = None,
        record_trace: bool = False,
    ) -> RolloutResult:
        """Simulate a batch driven by ``actors``.

        Parameters
        ----------
        initial : VehicleState
            Fields of shape (B, A); vehicle 0 is the ego.
        actors : sequence of Actor
            In order of precedence: a vehicle takes the action of the last
            actor that controls it; every vehicle must be controlled.
        seeds : Tensor of int64, shape (B,)
            Per-rollout seeds (the actors' counter-based noise).
        params : sequence of (Tensor of shape (B, P) or None), optional
            Each actor's per-rollout parameter block, in the order of
            ``actors``, passed to its ``init``; default None for every actor.
        record_trace : bool, default=False
            Also return the trajectories (memory ``O(B T A)``).

        Returns
        -------
        RolloutResult

        Raises
        ------
        ValueError
            For seeds of the wrong type or shape, a ``controlled`` mask that is
            not a bool tensor of shape (A,), a vehicle that no actor controls,
            or ``params`` that do not match the actors and the batch.
        """
        state = self.prepare(initial)
        b, n = state.batch_size, state.n_vehicles
        seeds = torch.as_tensor(seeds, device=self.device)
        if seeds.shape != (b,) or seeds.dtype != torch.int64:
            raise ValueError(
                f"seeds must be int64 of shape ({b},); got "
                f"{seeds.dtype} of shape {tuple(seeds.shape)}"
            )
        actors = list(actors)
        masks = self.controlled(actors, n)
        if params is None:
            params = [None] * len(actors)
        if len(params) != len(actors):
            raise ValueError(
                f"params must give one entry (a tensor or None) per actor: "
                f"{len(actors)} actors, {len(params)} params"
            )
        for k, p in enumerate(params):
            if p is not None and (p.dim() != 2 or p.shape[0] != b):
                raise ValueError(
                    f"params[{k}] must have shape ({b}, P); got {tuple(p.shape)}"
                )
        with torch.no_grad():
            return self._run(state, actors, masks, list(params), seeds, record_trace)

    def observe(self, state: VehicleState, seeds: Tensor, step: int = 0) -> Observation:
        """The observation of a state, as actors receive it at ``step``.

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
        state = self.prepare(state)
        with torch.no_grad():
            geo = self._geometry(state)
            return self._observation(state, geo, self._lidar(state, geo), seeds, step)

    def prepare(self, state: VehicleState) -> VehicleState:
        """``state`` on the simulator's device and dtype, validated (for start)."""
        return state.to(self.device, self.dtype).validate()

    # ---------------------------------------------------------------- internal

    def controlled(self, actors: Sequence[Actor], n_vehicles: int) -> list[Tensor]:
        """Every actor's ``controlled`` mask on the device, checked.

        Parameters
        ----------
        actors : sequence of Actor
        n_vehicles : int
            ``A``.

        Returns
        -------
        list of Tensor of bool, shape (A,)
            The masks :meth:`step` takes.

        Raises
        ------
        ValueError
            For no actor, a mask that is not a bool tensor of shape (A,), a
            vehicle that no actor controls, or an actor that reads the camera
            of a simulator without one.
        """
        if not actors:
            raise ValueError("give at least one actor")
        if self.camera is None and _reads_camera(actors):
            names = [type(a).__name__ for a in actors if reads_camera(a)]
            raise ValueError(
                f"{', '.join(names)} reads the camera, and this simulator has none; "
                "build the Simulator with camera=... (avrisk.render.RayCastCamera)"
            )
        masks = []
        for k, actor in enumerate(actors):
            mask = torch.as_tensor(actor.controlled)
            if mask.dtype != torch.bool or mask.shape != (n_vehicles,):
                raise ValueError(
                    f"actor {k} ({type(actor).__name__}): controlled must be a bool "
                    f"tensor of shape ({n_vehicles},); got {mask.dtype} of shape "
                    f"{tuple(mask.shape)}"
                )
            masks.append(mask.to(self.device))
        covered = torch.stack(masks).any(dim=0)
        if not bool(covered.all()):
            missing = torch.nonzero(~covered).flatten().tolist()
            raise ValueError(
                f"vehicles {missing} are controlled by no actor; every vehicle "
                "needs one (set its entry of some actor's controlled)"
            )
        return masks

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

    def _scan(self, state: VehicleState, cos: Tensor, sin: Tensor) -> LidarScan:
        """The lidar; eager on a CPU, in cache-sized slices of the batch.

        Eager, every other vehicle is scanned at once (temporaries of
        ``A (A - 1) R`` elements per rollout) while the whole batch's fit in
        one slice, and beyond that one vehicle at a time (``A R`` per rollout,
        ``A - 1`` times as many operations): on one CPU thread 18% and 9%
        faster per step of ``highway_default`` at batches of 1,024 and 8,192,
        and unchanged at 64, which scans all at once either way (BENCHMARKS.md
        "Simulator throughput"). Compiled, always
        one at a time (:func:`avrisk.sim.lidar.nearest_box`). The same values
        every way.
        """
        beams = self._beams
        assert beams is not None
        a, n_beams = state.n_vehicles, self.config.n_lidar_beams
        at_once = a * (a - 1) * n_beams
        large = state.x.shape[0] * at_once > _EAGER_CHUNK_TESTS
        one_at_a_time = True if large and cos.device.type == "cpu" else None
        per_rollout = a * n_beams if one_at_a_time else at_once

        def scan(state: VehicleState, cos: Tensor, sin: Tensor) -> LidarScan:
            return lidar_scan(
                state,
                cos,
                sin,
                self.road,
                *beams,
                self.config.lidar_range,
                one_at_a_time,
            )

        args = (state, cos, sin)
        return in_slices(scan, args, per_rollout, _EAGER_CHUNK_TESTS, cos.device)

    def _lidar(self, state: VehicleState, geo: _Geometry) -> LidarScan | None:
        return None if self._beams is None else self._scan(state, geo.cos, geo.sin)

    def _camera_frame(
        self, state: VehicleState, actors: Sequence[Actor]
    ) -> CameraFrame | None:
        """The ego camera's image when an actor reads it, else None."""
        if self.camera is None or not _reads_camera(actors):
            return None
        return self.camera(state)

    def _observation(
        self,
        state: VehicleState,
        geo: _Geometry,
        lidar: LidarScan | None,
        seeds: Tensor,
        step: int | Tensor,
        camera: CameraFrame | None = None,
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
            camera=camera,
        )

    def _noise(self, request: NoiseRequest | None, obs: Observation) -> Tensor | None:
        """The step's standard-normal noise for one actor, (B, *shape), or None."""
        if request is None:
            return None
        dtype = self.dtype if request.dtype is None else request.dtype
        return normal(obs.seeds, obs.step, request.stream, request.shape, dtype=dtype)

    def _act(
        self,
        obs: Observation,
        actors: Sequence[Actor],
        masks: Sequence[Tensor],
        states: Sequence[Any],
    ) -> tuple[Tensor, Tensor, tuple[Any, ...]]:
        """Every vehicle's (accel, steer), (B, A), from its controlling actor.

        Returns the actions and the actors' next states.
        """
        accel = steer = None
        new_states = []
        for actor, mask, memory in zip(actors, masks, states, strict=True):
            action, memory = actor.act(obs, memory, self._noise(actor.noise, obs))
            new_states.append(memory)
            mine = action.accel.to(self.dtype), action.steer.to(self.dtype)
            if accel is None or steer is None:
                accel, steer = mine
            else:
                accel = torch.where(mask, mine[0], accel)
                steer = torch.where(mask, mine[1], steer)
        assert accel is not None and steer is not None
        return accel, steer, tuple(new_states)

    def start(
        self,
        state: VehicleState,
        actors: Sequence[Actor],
        seeds: Tensor,
        params: Sequence[Tensor | None],
    ) -> tuple[RolloutCarry, Tensor]:
        """The carry at ``t = 0``: the state evaluated, the actors initialised.

        Parameters
        ----------
        state : VehicleState
            Fields of shape (B, A) on the simulator's device and dtype.
        actors : sequence of Actor
        seeds : Tensor of int64, shape (B,)
        params : sequence of (Tensor of shape (B, P) or None)
            One per actor, passed to its ``init``.

        Returns
        -------
        carry : RolloutCarry
        ttc : Tensor of shape (B,)
            The measure's instantaneous value at ``t = 0`` [s].
        """
        geo = self._geometry(state)
        ttc = self._ttc(state, geo.cos, geo.sin)
        ego_overlap = geo.overlap[:, 0, :]
        crash = ego_overlap.any(dim=-1)
        partner = torch.where(crash, ego_overlap.to(torch.int8).argmax(dim=-1), -1)
        hit_how = contact(
            state, geo.cos, geo.sin, partner.clamp_min(0), self.road.lane_width
        )
        lidar = self._lidar(state, geo) if _reads_lidar(actors) else None
        camera = self._camera_frame(state, actors)
        obs = self._observation(state, geo, lidar, seeds, 0, camera)
        carry = RolloutCarry(
            state=state,
            geo=geo,
            actors=tuple(a.init(obs, p) for a, p in zip(actors, params, strict=True)),
            measure=self.measure.init(ttc),
            alive=~crash,
            crash=crash,
            # contiguous, as step returns them: a compiled step guards on strides
            offroad=geo.offroad[:, 0].contiguous(),
            reversing=geo.reversing[:, 0].contiguous(),
            steps=torch.zeros_like(seeds),
            status=torch.full_like(crash, int(Status.OK), dtype=torch.int8),
            partner=partner,
            contact=torch.where(crash, hit_how, int(Contact.NONE)),
        )
        return carry, ttc

    def step(
        self,
        carry: RolloutCarry,
        t: int | Tensor,
        seeds: Tensor,
        actors: Sequence[Actor],
        masks: Sequence[Tensor],
    ) -> tuple[RolloutCarry, Tensor]:
        """One simulation step, from time ``t dt`` to ``(t + 1) dt``: a pure function.

        Observe the carried state, act, move the rollouts still alive, evaluate
        the new state. No host synchronisation and no Python loop over vehicles
        or rollouts: it runs under ``torch.compile(fullgraph=True)`` (with
        ``t`` a tensor, so that one graph serves every step) and under
        autograd (gradients flow to the initial state and the actors'
        floating parameters; :meth:`run` switches them off).

        Parameters
        ----------
        carry : RolloutCarry
            At time ``t`` (from :meth:`start` or the previous step).
        t : int or Tensor of int64, shape () or (B,)
            Index of the step's start time; the actors see it as ``obs.step``.
            One per rollout when they are at different steps (some were
            restarted, :meth:`RolloutCarry.with_rows`).
        seeds : Tensor of int64, shape (B,)
        actors : sequence of Actor
        masks : sequence of Tensor of bool, shape (A,)
            Each actor's ``controlled`` mask on the device (checked by
            :meth:`run`).

        Returns
        -------
        carry : RolloutCarry
            At time ``t + 1``.
        ttc : Tensor of shape (B,)
            The measure's instantaneous value at ``t + 1`` [s].
        """
        state, geo, alive = carry.state, carry.geo, carry.alive
        lidar = self._lidar(state, geo) if _reads_lidar(actors) else None
        camera = self._camera_frame(state, actors)
        obs = self._observation(state, geo, lidar, seeds, t, camera)
        accel, steer, memory = self._act(obs, actors, masks, carry.actors)
        acted = torch.isfinite(accel).all(dim=-1) & torch.isfinite(steer).all(-1)
        status = torch.where(alive & ~acted, int(Status.ACTOR_FAILED), carry.status)
        alive = alive & acted
        dt, limits = self.config.dt, self.limits
        moved = bicycle_step(state, accel, steer, dt, limits, (geo.cos, geo.sin))
        state = moved.where(alive, state)
        geo = self._geometry(state)
        ttc = self._ttc(state, geo.cos, geo.sin)
        ego_overlap = geo.overlap[:, 0, :]
        hit = alive & ego_overlap.any(dim=-1)
        partner = torch.where(
            hit, ego_overlap.to(torch.int8).argmax(dim=-1), carry.partner
        )
        lane_width = self.road.lane_width
        hit_how = contact(state, geo.cos, geo.sin, partner.clamp_min(0), lane_width)
        return RolloutCarry(
            state=state,
            geo=geo,
            actors=memory,
            measure=self.measure.update(carry.measure, ttc, alive),
            alive=alive & ~hit,
            crash=carry.crash | hit,
            offroad=carry.offroad | (alive & geo.offroad[:, 0]),
            reversing=carry.reversing | (alive & geo.reversing[:, 0]),
            steps=torch.where(alive, t + 1, carry.steps),
            status=status,
            partner=partner,
            contact=torch.where(hit, hit_how, carry.contact),
        ), torch.where(alive, ttc, math.inf)

    def _run(
        self,
        state: VehicleState,
        actors: list[Actor],
        masks: list[Tensor],
        params: list[Tensor | None],
        seeds: Tensor,
        record_trace: bool,
    ) -> RolloutResult:
        n_steps = self.config.n_steps
        carry, ttc = self.start(state, actors, seeds, params)
        step = self._step
        frames: list[tuple[Tensor, ...]] = []
        if record_trace:
            frames.append(_frame(carry.state, torch.ones_like(carry.alive), ttc))
        for t in range(n_steps):
            # The one host synchronisation per step: stop once all have stopped.
            if not bool(carry.alive.any()):
                break
            alive = carry.alive
            index = torch.tensor(t, device=self.device) if self.compile else t
            carry, ttc = step(carry, index, seeds, actors, masks)
            if record_trace:
                frames.append(_frame(carry.state, alive & (carry.steps == t + 1), ttc))
        trace = _trace(frames, n_steps) if record_trace else None
        f = self.measure.finalize(carry.measure)
        return RolloutResult(
            f=torch.where(carry.status == int(Status.OK), f, math.nan),
            crash=carry.crash,
            offroad=carry.offroad,
            reversing=carry.reversing,
            steps=carry.steps,
            status=carry.status,
            collision_with=carry.partner,
            contact=carry.contact,
            trace=trace,
        )


def _reads_lidar(actors: Sequence[Actor]) -> bool:
    """Whether some actor reads the lidar (else it is not scanned; same results)."""
    return any(reads_lidar(actor) for actor in actors)


def _reads_camera(actors: Sequence[Actor]) -> bool:
    """Whether some actor reads the ego camera (else it is not rendered)."""
    return any(reads_camera(actor) for actor in actors)


def _frame(state: VehicleState, alive: Tensor, ttc: Tensor) -> tuple[Tensor, ...]:
    """One frame of a :class:`Trace` (``ttc`` already ``inf`` where not alive)."""
    return (state.x, state.y, state.heading, state.speed, alive, ttc)


def _trace(frames: list[tuple[Tensor, ...]], n_steps: int) -> Trace:
    """The recorded frames stacked, padded to ``T + 1`` if all stopped early."""
    while len(frames) < n_steps + 1:  # everyone stopped early
        x, y, heading, speed, live, t = frames[-1]
        dead = torch.zeros_like(live)
        frames.append((x, y, heading, speed, dead, torch.full_like(t, math.inf)))
    return Trace(*(torch.stack(parts, dim=1) for parts in zip(*frames, strict=True)))
