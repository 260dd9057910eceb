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
Eager, a step is a few hundred small tensor operations, and ray casting on a
CPU goes through large batches in cache-sized slices (:mod:`avrisk.sim.sensing`).
``compile=True`` (or ``AVRISK_COMPILE=1``) makes the step one graph, several
times the eager throughput at large batches, bit-identical, after a
compilation per new batch size that is cached on disk across runs. The
figures and their commands: BENCHMARKS.md, "Simulator throughput".

The simulator's settings are :class:`~avrisk.sim.config.SimConfig`; the
sensing of a state (geometry, lidar, camera, the observation) is
:class:`~avrisk.sim.sensing.Sensors`; the carry, the results and the traces
are in :mod:`avrisk.sim.rollout`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from avrisk.sim.actors import act, controlled_masks
from avrisk.sim.camera import Camera
from avrisk.sim.collision import Contact, contact
from avrisk.sim.config import SimConfig, compile_requested
from avrisk.sim.dynamics import bicycle_step
from avrisk.sim.interfaces import Actor, SafetyMeasure
from avrisk.sim.observation import Observation
from avrisk.sim.road import Road
from avrisk.sim.rollout import (
    RolloutCarry,
    RolloutResult,
    Status,
    stack_trace,
    trace_frame,
)
from avrisk.sim.sensing import (
    Sensors,
    any_reads_lidar,
    in_cache_slices,
)
from avrisk.sim.state import VehicleState

__all__ = ["Simulator"]


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
        needs a C++ compiler): one graph per step, actors included, several
        times faster than eager at large batches after a one-off compilation
        per new batch size (the first size gets fixed-shape kernels, later
        sizes share one dynamic-shape set; compiled code is cached on disk
        across runs; BENCHMARKS.md, "Simulator throughput"). Results are the
        same as in eager mode, bit for bit. None reads the environment
        variable ``AVRISK_COMPILE`` (``1`` to compile,
        :func:`~avrisk.sim.config.compile_requested`); default off.

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
        self.sensors = Sensors(road, config, camera, dtype, self.device)
        self.compile = compile_requested(compile)
        per_pair = measure.tests_per_pair
        self._ttc = in_cache_slices(measure.instant, lambda a: (a - 1) * per_pair)
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
        sensors = self.sensors
        with torch.no_grad():
            geo = sensors.geometry(state)
            return sensors.observation(
                state, geo, sensors.lidar(state, geo), seeds, step
            )

    def prepare(self, state: VehicleState) -> VehicleState:
        """``state`` on the simulator's device and dtype, validated (for start)."""
        return state.to(self.device, self.dtype).validate()

    # ---------------------------------------------------------------- internal

    def controlled(self, actors: Sequence[Actor], n_vehicles: int) -> list[Tensor]:
        """Every actor's ``controlled`` mask on the device, checked.

        See :func:`~avrisk.sim.actors.controlled_masks`; the masks are what
        :meth:`step` takes.
        """
        return controlled_masks(
            actors, n_vehicles, self.device, has_camera=self.camera is not None
        )

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
        sensors = self.sensors
        geo = sensors.geometry(state)
        ttc = self._ttc(state, geo.cos, geo.sin)
        ego_overlap = geo.overlap[:, 0, :]
        crash = ego_overlap.any(dim=-1)
        partner = torch.where(crash, ego_overlap.to(torch.int8).argmax(dim=-1), -1)
        hit_how = contact(
            state, geo.cos, geo.sin, partner.clamp_min(0), self.road.lane_width
        )
        lidar = sensors.lidar(state, geo) if any_reads_lidar(actors) else None
        camera = sensors.camera_frame(state, actors)
        obs = sensors.observation(state, geo, lidar, seeds, 0, camera)
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
        state, geo, alive, sensors = carry.state, carry.geo, carry.alive, self.sensors
        lidar = sensors.lidar(state, geo) if any_reads_lidar(actors) else None
        camera = sensors.camera_frame(state, actors)
        obs = sensors.observation(state, geo, lidar, seeds, t, camera)
        accel, steer, memory = act(obs, actors, masks, carry.actors, self.dtype)
        acted = torch.isfinite(accel).all(dim=-1) & torch.isfinite(steer).all(-1)
        status = torch.where(alive & ~acted, int(Status.ACTOR_FAILED), carry.status)
        alive = alive & acted
        dt, limits = self.config.dt, self.limits
        moved = bicycle_step(state, accel, steer, dt, limits, (geo.cos, geo.sin))
        state = moved.where(alive, state)
        geo = sensors.geometry(state)
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
            frames.append(trace_frame(carry.state, torch.ones_like(carry.alive), ttc))
        for t in range(n_steps):
            # The one host synchronisation per step: stop once all have stopped.
            if not bool(carry.alive.any()):
                break
            alive = carry.alive
            index = torch.tensor(t, device=self.device) if self.compile else t
            carry, ttc = step(carry, index, seeds, actors, masks)
            if record_trace:
                frames.append(
                    trace_frame(carry.state, alive & (carry.steps == t + 1), ttc)
                )
        trace = stack_trace(frames, n_steps) if record_trace else None
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
