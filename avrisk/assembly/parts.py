"""The parts of a scenario's simulation, each built from its spec.

* :func:`road_from_spec`, :func:`sim_config_from_spec`,
  :func:`safety_measure_from_spec`, :func:`camera_from_spec` -- the static
  pieces;
* :func:`param_layout`, :func:`base_distribution` -- the scenario's named
  ``X`` and ``P0``, with the learned drivers' ``xi`` block (its dimension and
  the shipped prior ``N(mu0, Sigma0)``);
* :func:`initial_state` -- ``ScenarioParams`` (B, A) to the simulator's
  ``VehicleState`` in road coordinates;
* :func:`driver_params` -- per-slot IDM+MOBIL parameters as (B, A) tensors
  (slot 0 carries the ego policy's parameters);
* :func:`learned_drivers`, :func:`other_drivers`, :func:`ego_actor` -- the
  actors besides IDM+MOBIL.

:class:`~avrisk.assembly.builder.ScenarioSimulator` binds them together.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents import (
    IDMParams,
    LearnedDriver,
    as_ego_actor,
    get_driver_model,
    get_policy,
)
from avrisk.agents.drivers import XI_DIM, DriverNet, load_xi_prior
from avrisk.agents.drivers.lane_change import LaneChangeParams, LaneChangingDriver
from avrisk.assembly.traffic import TrafficDrivers
from avrisk.rare import Product
from avrisk.render import DEFAULT_VEHICLE_HEIGHT, CameraModel, RayCastCamera
from avrisk.safety import get_safety_measure
from avrisk.scenario import ParamLayout, ScenarioParams, build_base_distribution
from avrisk.scenario.components import IDM_MOBIL, LEARNED, DriverSpec
from avrisk.scenario.sensors import CameraSpec
from avrisk.scenario.spec import ScenarioSpec
from avrisk.sim.config import SimConfig
from avrisk.sim.interfaces import Actor, SafetyMeasure
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

__all__ = [
    "base_distribution",
    "camera_from_spec",
    "driver_params",
    "ego_actor",
    "full_float32_on_gpus",
    "initial_state",
    "learned_drivers",
    "other_drivers",
    "param_layout",
    "road_from_spec",
    "safety_measure_from_spec",
    "sim_config_from_spec",
]

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
    """The simulator's settings (time step, horizon, lidar)."""
    sim = spec.simulation
    return SimConfig(
        dt=sim.dt,
        horizon=sim.horizon,
        n_lidar_beams=sim.n_lidar_beams,
        lidar_range=sim.lidar_range,
    )


def safety_measure_from_spec(
    spec: ScenarioSpec,
    *,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
    allow_import: bool = False,
) -> SafetyMeasure:
    """The scenario's safety measure ``f`` with its params.

    A measure is offered ``n_rays`` (ray TTC's ray count), ``device`` and
    ``dtype`` and takes those its signature names.
    """
    safety = spec.safety
    return get_safety_measure(
        safety.measure,
        safety.params,
        allow_import=allow_import,
        n_rays=safety.n_rays,
        device=device,
        dtype=dtype,
    )


def _other_driver_models(
    drivers: list[DriverSpec],
) -> list[tuple[str, dict[str, Any]]]:
    """The driver models besides IDM+MOBIL and learned, each once, with params.

    Raises
    ------
    ValueError
        If one model name comes with two different ``params`` (one actor
        drives all vehicles of a model).
    """
    found: dict[str, dict[str, Any]] = {}
    for d in drivers:
        if d.model in (IDM_MOBIL, LEARNED):
            continue
        if found.setdefault(d.model, d.params) != d.params:
            raise ValueError(
                f"driver model {d.model!r} is given twice with different params; "
                "one model drives all its vehicles with one set of params"
            )
    return list(found.items())


def camera_from_spec(
    spec: ScenarioSpec,
    *,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
) -> RayCastCamera:
    """The ego camera of a scenario: its ``camera`` (or the defaults), slot heights.

    A slot without a ``height`` gets
    :data:`~avrisk.render.DEFAULT_VEHICLE_HEIGHT`.
    """
    cam = spec.camera if spec.camera is not None else CameraSpec()
    return RayCastCamera(
        road_from_spec(spec),
        CameraModel(**cam.model_dump()),
        heights=[
            DEFAULT_VEHICLE_HEIGHT if v.height is None else v.height
            for v in spec.vehicles
        ],
        device=device,
        dtype=dtype,
    )


def param_layout(spec: ScenarioSpec) -> ParamLayout:
    """The column layout of a scenario's ``X`` (``xi`` block: ``XI_DIM`` columns)."""
    return ParamLayout.from_spec(spec, XI_DIM)


def base_distribution(
    spec: ScenarioSpec, traffic: TrafficDrivers | None = None
) -> Product:
    """``P0`` of a scenario, with the learned drivers' ``xi`` prior.

    Parameters
    ----------
    spec : ScenarioSpec
    traffic : TrafficDrivers, optional
        Whose prior the ``xi`` block is (default: the shipped drivers').

    Returns
    -------
    avrisk.rare.Product
        See :func:`avrisk.scenario.build_base_distribution`; ``dim`` equals
        ``param_layout(spec).dim``.
    """
    prior = None
    if spec.has_learned_drivers:
        prior = load_xi_prior() if traffic is None else traffic.prior()
    return build_base_distribution(spec, prior)


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


def learned_drivers(
    net: DriverNet, controlled: torch.Tensor, spec: ScenarioSpec, road: Road
) -> LearnedDriver | LaneChangingDriver:
    """The actor of a scenario's learned drivers, changing lanes if the spec says so.

    They drive with the emergency brake their weights carry (``net.guard``,
    :mod:`avrisk.agents.drivers.guard`); the ``lidar_imitation`` ego, the same
    network, drives without it.

    Parameters
    ----------
    net : DriverNet
    controlled : Tensor of bool, shape (A,)
        The learned drivers' slots.
    spec : ScenarioSpec
        Its ``learned_drivers`` section: sampled or mean actions, lane changes.
    road : Road

    Returns
    -------
    LearnedDriver or LaneChangingDriver
    """
    settings = spec.learned_drivers
    driver = LearnedDriver(
        net,
        controlled=controlled,
        stochastic=settings.stochastic,
        noise_steps=spec.simulation.n_steps if settings.noise_in_x else None,
        guard=net.guard,
    )
    if settings.lane_changes is None:
        return driver
    params = LaneChangeParams(**settings.lane_changes.settings())
    return LaneChangingDriver(driver, road, params)


def full_float32_on_gpus() -> None:
    """Make float32 on a CUDA device full float32: no TensorFloat-32.

    torch lets cuDNN convolutions (PilotNet's) round their inputs to TF32's
    10-bit mantissa by default; a simulator records its precision as float32
    (``SimulationObjective.computed_with``) and agrees with the CPU within the
    stated tolerance only without it. The switches are process-wide.
    """
    torch.backends.cudnn.allow_tf32 = False
    torch.backends.cuda.matmul.allow_tf32 = False


def other_drivers(
    types: list[DriverSpec], context: dict[str, Any], allow_import: bool
) -> list[Actor]:
    """One actor per driver model besides IDM+MOBIL and learned, for its vehicles.

    ``types`` are the driver specs of vehicles ``1..A-1``; ``context`` is what
    every factory is offered (``n_vehicles``, ``road``, ``device``, ``dtype``),
    with ``controlled`` (bool (A,)) added per model.
    """
    device = context["device"]
    return [
        get_driver_model(
            name,
            params,
            allow_import=allow_import,
            controlled=torch.tensor(
                [False] + [t.model == name for t in types], device=device
            ),
            **context,
        )
        for name, params in _other_driver_models(types)
    ]


def ego_actor(
    spec: ScenarioSpec,
    net: DriverNet | None,
    context: dict[str, Any],
    allow_import: bool,
) -> Actor:
    """The scenario's ego policy (other than IDM+MOBIL) as the actor of slot 0.

    Its factory is offered ``net`` (the driver network, or None) besides
    ``context``.
    """
    return as_ego_actor(
        get_policy(
            spec.ego.policy,
            spec.ego.params,
            allow_import=allow_import,
            net=net,
            **context,
        ),
        spec.n_vehicles,
        device=context["device"],
    )
