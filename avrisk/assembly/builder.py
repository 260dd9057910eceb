"""From a scenario spec and flat ``X`` to the simulator, its actors and its measure.

The one place that joins :mod:`avrisk.scenario` (data) with :mod:`avrisk.sim`,
:mod:`avrisk.agents` and :mod:`avrisk.safety`:

* :mod:`avrisk.assembly.parts` -- the static pieces (road, configuration,
  measure, camera), the scenario's named ``X`` and ``P0``, the initial state
  and the drivers' parameters from ``X``, the actors besides IDM+MOBIL;
* :class:`ScenarioSimulator` -- all of them bound together: flat ``X``
  (B, D) and seeds (B,) in, ``RolloutResult`` out.

Actors, in order of precedence (:meth:`ScenarioSimulator.actors`): the
IDM+MOBIL drivers (:class:`~avrisk.agents.idm.IDMDriver`, one batched pass for
all their slots; an ``idm_mobil`` ego is one more of them, slot 0), the
learned drivers (:class:`~avrisk.agents.drivers.LearnedDriver`, one batched
pass, parameter block the rollout's ``xi`` columns of ``X``, shared by all
learned drivers of the rollout, and their ``noise`` columns when the action
noise is in ``X``), and any other ego policy (registered by name,
e.g. ``lidar_imitation``), which controls slot 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from avrisk.agents import (
    IDMDriver,
)
from avrisk.agents.drivers import DriverNet, load_driver_net
from avrisk.assembly.parts import (
    camera_from_spec,
    driver_params,
    ego_actor,
    full_float32_on_gpus,
    initial_state,
    learned_drivers,
    other_drivers,
    param_layout,
    road_from_spec,
    safety_measure_from_spec,
    sim_config_from_spec,
)
from avrisk.assembly.traffic import TrafficDrivers
from avrisk.scenario import ScenarioParams
from avrisk.scenario.components import IDM_MOBIL
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.camera import reads_camera
from avrisk.sim.interfaces import Actor, deterministic
from avrisk.sim.rollout import RolloutCarry, RolloutResult
from avrisk.sim.simulator import Simulator
from avrisk.sim.state import VehicleState

__all__ = ["ScenarioSimulator", "Step"]

#: ``step(carry, t) -> (carry, ttc)``, see :meth:`ScenarioSimulator.start`.
Step = Callable[[RolloutCarry, "int | torch.Tensor"], tuple[RolloutCarry, torch.Tensor]]


class ScenarioSimulator:
    """A scenario bound to a simulator: flat ``X`` and seeds in, rollouts out.

    Parameters
    ----------
    spec : ScenarioSpec
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32
    allow_import : bool, default=False
    traffic : TrafficDrivers, optional
        Other learned traffic drivers (:mod:`avrisk.assembly.traffic`); the
        ego keeps the shipped network. Default: the shipped drivers, the
        same network as the ego's.

    Attributes
    ----------
    spec : ScenarioSpec
    layout : ParamLayout
        Column layout of ``X``.
    road : avrisk.sim.road.Road
    config : avrisk.sim.config.SimConfig
    simulator : avrisk.sim.simulator.Simulator
    net : DriverNet or None
        The shipped driver network (on ``device``) when a learned driver or
        the ``lidar_imitation`` ego needs it (the traffic's too, unless
        ``traffic`` names others).
    traffic : TrafficDrivers or None
    ego_policy : Actor or None
        The ego policy when it is not IDM+MOBIL (then slot 0 of the IDM+MOBIL
        drivers); it controls slot 0.
    camera : avrisk.render.RayCastCamera or None
        The ego camera (:func:`camera_from_spec`) when the spec has one or the
        ego reads one (``reads_camera``), else None.
    """

    def __init__(
        self,
        spec: ScenarioSpec,
        *,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
        allow_import: bool = False,
        traffic: TrafficDrivers | None = None,
    ) -> None:
        self.spec = spec
        self.traffic = traffic
        self.layout = param_layout(spec)
        self.road = road_from_spec(spec)
        self.config = sim_config_from_spec(spec)
        self.device = torch.device(device)
        self.dtype = dtype
        if self.device.type == "cuda":
            full_float32_on_gpus()
        idm_ego = spec.ego.policy == IDM_MOBIL
        types = [spec.driver_type(j) for j in range(1, spec.n_vehicles)]
        # Per slot (A,): driven by the driver network / by IDM+MOBIL.
        self._learned = torch.tensor(spec.learned_slots, device=self.device)
        self._idm = torch.tensor(
            [idm_ego] + [t.model == IDM_MOBIL for t in types], device=self.device
        )
        context = dict(
            n_vehicles=spec.n_vehicles, road=self.road, device=self.device, dtype=dtype
        )
        self._other_drivers = other_drivers(types, context, allow_import)
        needs_net = bool(self._learned.any()) or not idm_ego
        self.net: DriverNet | None = (
            load_driver_net().to(self.device) if needs_net else None
        )
        traffic_net = self.net
        if traffic is not None and self.net is not None:
            traffic_net = traffic.net().to(self.device)
        self._learned_driver = (
            learned_drivers(traffic_net, self._learned, spec, self.road)
            if traffic_net is not None and bool(self._learned.any())
            else None
        )
        self.ego_policy: Actor | None = (
            None if idm_ego else ego_actor(spec, self.net, context, allow_import)
        )
        self.camera = (
            camera_from_spec(spec, device=device, dtype=dtype)
            if spec.camera is not None or reads_camera(self.ego_policy)
            else None
        )
        self.simulator = Simulator(
            self.road,
            self.config,
            measure=safety_measure_from_spec(
                spec, device=device, dtype=dtype, allow_import=allow_import
            ),
            device=device,
            dtype=dtype,
            camera=self.camera,
        )

    @property
    def n_steps(self) -> int:
        """Time steps per full rollout ``T``."""
        return math.ceil(self.spec.simulation.horizon / self.spec.simulation.dt - 1e-9)

    @property
    def deterministic(self) -> bool:
        """Whether every actor vouches that a rollout depends only on ``X`` and seed.

        The built-in drivers do; an ego policy or driver model the scenario
        names may not (``deterministic = False``: the external ego, see
        :func:`avrisk.sim.interfaces.deterministic`): its new runs check it
        first (every resume checks recorded rollouts, whatever the actors).
        """
        named = [*self._other_drivers, self.ego_policy]
        return all(deterministic(actor) for actor in named if actor is not None)

    def rollout(
        self, x: ArrayLike, seeds: ArrayLike, *, record_trace: bool = False
    ) -> RolloutResult:
        """Simulate a batch of scenario realisations.

        Parameters
        ----------
        x : array_like of shape (B, D)
            Flat scenario samples in the layout of ``self.layout``.
        seeds : array_like of int, shape (B,)
            One seed per rollout (see :func:`avrisk.rare.problem.sample_seeds`).
        record_trace : bool, default=False
            Also return the trajectories (memory grows as ``B T A``).

        Returns
        -------
        RolloutResult
            ``f`` (B,) minimum TTC [s], ``crash``/``offroad``/``reversing`` (B,)
            bool, ``steps`` (B,) int64, ``status``/``contact`` (B,) int8,
            ``collision_with`` (B,) int64, ``trace`` or None.
        """
        state, actors, blocks, seeds_t = self._prepare(x, seeds)
        return self.simulator.run(
            state, actors, seeds_t, params=blocks, record_trace=record_trace
        )

    def start(self, x: ArrayLike, seeds: ArrayLike) -> tuple[RolloutCarry, Step]:
        """The state at ``t = 0`` and the simulation step, for stepping by hand.

        For compiling or differentiating a rollout (:meth:`Simulator.step`):
        ``carry, step = sim.start(x, seeds)``, then ``carry, ttc = step(carry,
        t)`` for ``t = 0 .. T-1``; ``torch.compile(step, fullgraph=True)``
        compiles. Gradients are on unless the caller switches them off.

        Parameters
        ----------
        x : array_like of shape (B, D)
        seeds : array_like of int, shape (B,)

        Returns
        -------
        carry : RolloutCarry
            At ``t = 0``.
        step : callable
            ``step(carry, t) -> (carry, ttc)``: :meth:`Simulator.step` with
            this batch's seeds, actors and masks bound (``step(carry, t,
            seeds=...)`` overrides the seeds, after :meth:`restart`).
        """
        state, actors, blocks, seeds_t = self._prepare(x, seeds)
        sim = self.simulator
        masks = sim.controlled(actors, state.n_vehicles)
        carry, _ = sim.start(state, actors, seeds_t, blocks)
        step = partial(sim.step, seeds=seeds_t, actors=tuple(actors), masks=masks)
        return carry, step

    def restart(
        self, carry: RolloutCarry, rows: torch.Tensor, x: ArrayLike, seeds: ArrayLike
    ) -> RolloutCarry:
        """``carry`` of a batch from :meth:`start` with some rollouts started anew.

        The rollouts where ``rows`` is true start again from ``x`` and
        ``seeds``, at ``t = 0``; the others are untouched. The batch's
        ``step`` goes on stepping every rollout: a scenario's actors keep what
        differs between rollouts in their parameter blocks and states (the
        carry), the IDM+MOBIL drivers' parameters are the same for every
        rollout. Step it with a step index per rollout and the new seeds:
        ``step(carry, t, seeds=seeds)``, ``t`` of shape (B,).

        Parameters
        ----------
        carry : RolloutCarry
            A batch of ``B`` rollouts of this scenario.
        rows : Tensor of bool, shape (B,)
            The rollouts to restart (``n`` of them).
        x : array_like of shape (n, D)
            Their scenario samples, in the order of ``rows``.
        seeds : array_like of int, shape (n,)

        Returns
        -------
        RolloutCarry
        """
        state, actors, blocks, seeds_t = self._prepare(x, seeds)
        fresh, _ = self.simulator.start(state, actors, seeds_t, blocks)
        return carry.with_rows(rows.to(self.device), fresh)

    def _prepare(
        self, x: ArrayLike, seeds: ArrayLike
    ) -> tuple[VehicleState, list[Actor], list[torch.Tensor | None], torch.Tensor]:
        """Initial state, actors, their parameter blocks and seeds of a batch."""
        params = ScenarioParams.from_flat(np.asarray(x, dtype=np.float64), self.layout)
        seeds_t = torch.as_tensor(np.array(seeds, dtype=np.int64), device=self.device)
        if seeds_t.shape != (params.batch_size,):
            raise ValueError(
                f"seeds must have shape ({params.batch_size},); "
                f"got {tuple(seeds_t.shape)}"
            )
        state = initial_state(params, self.spec, device=self.device, dtype=self.dtype)
        actors, blocks = self.actors(params)
        return state, actors, blocks, seeds_t

    def actors(
        self, params: ScenarioParams
    ) -> tuple[list[Actor], list[torch.Tensor | None]]:
        """The actors of a batch, in order of precedence, and their parameters.

        Parameters
        ----------
        params : ScenarioParams
            The batch; the learned drivers of rollout ``b`` use ``params.xi[b]``
            (and ``params.noise[b]``).

        Returns
        -------
        actors : list of Actor
            IDM+MOBIL drivers, learned drivers, other driver models (one per
            model name), the ego policy: those the scenario has. Together they
            control every slot.
        blocks : list of (Tensor of shape (B, P) or None)
            Each actor's parameter block: ``xi`` (B, XI_DIM) for the learned
            drivers, followed by their innovations when they are in ``X``
            (``P = XI_DIM + 2 T C``), None for the others.
        """
        actors: list[Actor] = []
        blocks: list[torch.Tensor | None] = []
        if bool(self._idm.any()):
            p = driver_params(
                self.spec, params.batch_size, device=self.device, dtype=self.dtype
            )
            actors.append(
                IDMDriver(
                    p.validate(),
                    self.road,
                    wheelbase_fraction=self.config.wheelbase_fraction,
                    controlled=self._idm,
                )
            )
            blocks.append(None)
        if self._learned_driver is not None:
            actors.append(self._learned_driver)
            block = np.concatenate([params.xi, params.noise], axis=1)
            blocks.append(torch.from_numpy(block))
        actors += self._other_drivers
        blocks += [None] * len(self._other_drivers)
        if self.ego_policy is not None:
            actors.append(self.ego_policy)
            blocks.append(None)
        return actors, blocks

    def min_ttc(self, x: ArrayLike, seeds: ArrayLike) -> NDArray[np.float64]:
        """Minimum time-to-collision of each rollout [s], shape (B,), float64."""
        return self.rollout(x, seeds).f.detach().cpu().numpy().astype(np.float64)
