"""From a scenario spec and named parameters to simulator inputs, and rollouts.

This is the thin adapter between :mod:`avrisk.scenario` and :mod:`avrisk.sim`:

* :func:`road_from_spec`, :func:`sim_config_from_spec` -- the static pieces;
* :func:`initial_state` -- ``ScenarioParams`` (B, A) to the simulator's
  ``VehicleState`` in road coordinates;
* :func:`driver_params` -- per-slot IDM+MOBIL parameters as (B, A) tensors
  (slot 0 carries the ego policy's parameters);
* :class:`ScenarioSimulator` -- all of the above bound together: flat ``X``
  (B, D) and seeds (B,) in, ``RolloutResult`` out.

Drivers: every vehicle of a rollout is driven in one batched pass by IDM+MOBIL
(:class:`~avrisk.agents.idm.IDMDriver`), by the learned driver network with
the rollout's own ``xi`` (:class:`~avrisk.agents.drivers.LearnedDriver`, one
``xi`` row of ``X`` shared by all learned drivers of the rollout), or, when a
scenario has both, by a per-vehicle mix of the two
(:class:`~avrisk.agents.mixed.MixedDriver`). An ego with an IDM+MOBIL policy
is one more IDM+MOBIL vehicle (slot 0); the ``lidar_imitation`` ego is the
registered ego policy of that name, which replaces slot 0's action.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from avrisk.agents import (
    DriverModel,
    IDMDriver,
    IDMParams,
    LearnedDriver,
    MixedDriver,
    Policy,
    get_policy,
)
from avrisk.agents.drivers import DriverNet, load_driver_net
from avrisk.safety import SafetyMeasure, get_safety_measure
from avrisk.scenario.components import IDM_MOBIL
from avrisk.scenario.params import ParamLayout, ScenarioParams
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.road import Road
from avrisk.sim.simulator import RolloutResult, SimConfig, Simulator
from avrisk.sim.state import VehicleState

_IDM_FIELDS = (
    "desired_speed",
    "time_headway",
    "min_gap",
    "max_accel",
    "comfort_decel",
    "politeness",
    "lane_change_threshold",
)


def road_from_spec(spec: ScenarioSpec) -> Road:
    """The simulator's road for a scenario."""
    r = spec.road
    return Road(
        n_lanes=r.n_lanes,
        lane_width=r.lane_width,
        length=r.length,
        curvature=r.curvature,
    )


def sim_config_from_spec(spec: ScenarioSpec) -> SimConfig:
    """The simulator's settings (time step, horizon, lidar, TTC rays)."""
    sim = spec.simulation
    return SimConfig(
        dt=sim.dt,
        horizon=sim.horizon,
        n_lidar_beams=sim.n_lidar_beams,
        lidar_range=sim.lidar_range,
        n_ttc_rays=spec.safety.n_rays,
    )


def safety_measure_from_spec(
    spec: ScenarioSpec,
    *,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
) -> SafetyMeasure:
    """The scenario's safety measure ``f`` (ray TTC takes its ray count)."""
    safety = spec.safety
    if safety.measure == "min_ttc":
        return get_safety_measure(
            "min_ttc",
            n_rays=safety.n_rays,
            device=device,
            dtype=dtype,
        )
    return get_safety_measure(safety.measure)


def initial_state(
    params: ScenarioParams,
    spec: ScenarioSpec,
    *,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
) -> VehicleState:
    """Initial vehicle states of a batch of scenario realisations.

    Vehicle ``j`` starts at ``x = offset_j + s`` [m] along the road, ``y =
    (lane_j + 0.5) lane_width + t`` [m] from the right road edge, heading
    ``radians(heading)`` [rad] from the lane direction, with speed ``speed``
    [m/s]; its size comes from the slot.

    Parameters
    ----------
    params : ScenarioParams
        Batch of ``B`` realisations of ``A = spec.n_vehicles`` vehicles.
    spec : ScenarioSpec
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32

    Returns
    -------
    VehicleState
        Every field a tensor of shape (B, A); index 0 is the ego.
    """
    if params.n_vehicles != spec.n_vehicles:
        raise ValueError(
            f"params have {params.n_vehicles} vehicles, scenario {spec.name!r} has "
            f"{spec.n_vehicles}"
        )
    slots = spec.vehicles
    offset = np.array([v.offset for v in slots])
    lane_y = (np.array([v.lane for v in slots]) + 0.5) * spec.road.lane_width
    b = params.batch_size

    def tensor(a: NDArray[np.float64]) -> torch.Tensor:
        return torch.tensor(np.ascontiguousarray(a), dtype=dtype, device=device)

    def per_slot(values: list[float]) -> torch.Tensor:
        return tensor(
            np.broadcast_to(np.asarray(values, dtype=np.float64), (b, len(slots)))
        )

    return VehicleState(
        x=tensor(offset[None, :] + params.s),
        y=tensor(lane_y[None, :] + params.t),
        heading=tensor(np.deg2rad(params.heading)),
        speed=tensor(params.speed),
        length=per_slot([v.length for v in slots]),
        width=per_slot([v.width for v in slots]),
    )


def driver_params(
    spec: ScenarioSpec,
    batch_size: int,
    *,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
) -> IDMParams:
    """IDM+MOBIL parameters of every vehicle, ego (slot 0) included.

    Parameters
    ----------
    spec : ScenarioSpec
    batch_size : int
        ``B``; every rollout gets the same per-slot parameters.
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32

    Returns
    -------
    IDMParams
        Each field a tensor of shape (B, A) in the units of
        :class:`~avrisk.scenario.components.IDMSpec`; a learned driver's slot holds
        the defaults (MOBIL's model of it), as does the slot of an ego that is
        not ``idm_mobil``.
    """
    per_slot = [spec.driver_for(j) for j in range(spec.n_vehicles)]
    fields = {}
    for name in _IDM_FIELDS:
        row = torch.tensor(
            [getattr(d, name) for d in per_slot], dtype=dtype, device=device
        )
        fields[name] = row.expand(batch_size, -1).contiguous()
    return IDMParams(**fields)


class ScenarioSimulator:
    """A scenario bound to a simulator: flat ``X`` and seeds in, rollouts out.

    Parameters
    ----------
    spec : ScenarioSpec
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32

    Attributes
    ----------
    spec : ScenarioSpec
    layout : ParamLayout
        Column layout of ``X``.
    road : avrisk.sim.road.Road
    config : avrisk.sim.simulator.SimConfig
    simulator : avrisk.sim.simulator.Simulator
    net : DriverNet or None
        The shipped driver network (on ``device``) when a learned driver or
        the ``lidar_imitation`` ego needs it.
    ego_policy : Policy or None
        The ego policy when it is not IDM+MOBIL (slot 0 of the drivers).
    """

    def __init__(
        self,
        spec: ScenarioSpec,
        *,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
    ) -> None:
        self.spec = spec
        self.layout = ParamLayout.from_spec(spec)
        self.road = road_from_spec(spec)
        self.config = sim_config_from_spec(spec)
        self.device = torch.device(device)
        self.dtype = dtype
        self.simulator = Simulator(
            self.road,
            self.config,
            device=device,
            dtype=dtype,
            measure=safety_measure_from_spec(spec, device=device, dtype=dtype),
        )
        idm_ego = spec.ego.policy == IDM_MOBIL
        # Per slot (A,): driven by the driver network / by IDM+MOBIL.
        self._learned = torch.tensor(spec.learned_slots, device=self.device)
        self._idm = ~self._learned
        self._idm[0] = idm_ego
        needs_net = bool(self._learned.any()) or not idm_ego
        self.net: DriverNet | None = (
            load_driver_net().to(self.device) if needs_net else None
        )
        self.ego_policy: Policy | None = (
            None if idm_ego else get_policy(spec.ego.policy, net=self.net)
        )

    @property
    def n_steps(self) -> int:
        """Time steps per full rollout ``T``."""
        return math.ceil(self.spec.simulation.horizon / self.spec.simulation.dt - 1e-9)

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
            bool, ``steps`` (B,) int64, ``trace`` or None.
        """
        params = ScenarioParams.from_flat(np.asarray(x, dtype=np.float64), self.layout)
        seeds_t = torch.as_tensor(np.array(seeds, dtype=np.int64), device=self.device)
        if seeds_t.shape != (params.batch_size,):
            raise ValueError(
                f"seeds must have shape ({params.batch_size},); "
                f"got {tuple(seeds_t.shape)}"
            )
        state = initial_state(params, self.spec, device=self.device, dtype=self.dtype)
        with torch.no_grad():
            return self.simulator.run(
                state,
                self.drivers(params),
                seeds_t,
                ego_policy=self.ego_policy,
                record_trace=record_trace,
            )

    def drivers(self, params: ScenarioParams) -> DriverModel:
        """The driver model of a batch: IDM+MOBIL, learned, or a per-vehicle mix.

        Parameters
        ----------
        params : ScenarioParams
            The batch; the learned drivers of rollout ``b`` use ``params.xi[b]``.

        Returns
        -------
        DriverModel
            Acts for every vehicle, fields of shape (B, A).
        """
        learned = None
        if bool(self._learned.any()):
            assert self.net is not None
            xi = torch.from_numpy(np.ascontiguousarray(params.xi))
            learned = LearnedDriver(
                self.net, xi, stochastic=self.spec.learned_drivers.stochastic
            )
            if not bool(self._idm.any()):
                return learned
        idm = IDMDriver(
            driver_params(
                self.spec, params.batch_size, device=self.device, dtype=self.dtype
            ).validate(),
            self.road,
            wheelbase_fraction=self.config.wheelbase_fraction,
            drives=None if bool(self._idm.all()) else self._idm,
        )
        return idm if learned is None else MixedDriver(idm, learned, self._learned)

    def min_ttc(self, x: ArrayLike, seeds: ArrayLike) -> NDArray[np.float64]:
        """Minimum time-to-collision of each rollout [s], shape (B,), float64."""
        return self.rollout(x, seeds).f.detach().cpu().numpy().astype(np.float64)


def ttc_series(sim: ScenarioSimulator, result: RolloutResult) -> NDArray[np.float64]:
    """Minimum time-to-collision so far at every recorded step [s].

    Parameters
    ----------
    sim : ScenarioSimulator
        The simulator that produced ``result``.
    result : RolloutResult
        Recorded with ``record_trace=True``.

    Returns
    -------
    ndarray of shape (B, T+1)
        Running minimum over steps ``0..k`` of the ray TTC from the ego centre;
        constant after a rollout ends; ``inf`` while nothing approaches.
    """
    trace = result.trace
    if trace is None:
        raise ValueError("the rollout was run without record_trace=True")
    ttc = getattr(trace, "ttc", None)
    if ttc is None:  # pragma: no cover - depends on the simulator's trace
        raise NotImplementedError("the simulator's trace does not record TTC")
    series = ttc.detach().cpu().numpy().astype(np.float64)
    alive = trace.alive.detach().cpu().numpy().astype(bool)
    series = np.where(alive, series, np.inf)
    return np.minimum.accumulate(series, axis=1)
