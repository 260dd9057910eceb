"""The scenario spec: a YAML file validated into frozen Pydantic models.

A scenario names everything one rollout needs besides its random draw ``X``:
the road, the vehicle slots (slot 0 is the ego), the base distribution of the
initial conditions relative to each slot (paper, Sec. 5: ``S, T, W, V``), the
environment drivers, the ego policy, the simulator settings and the safety
measure. Example (the bundled ``highway_default`` is the full one)::

    road: {n_lanes: 6, lane_width: 3.7, length: 500.0}
    initial_conditions:
      s:       {lo: 80.0,  scale: 40.0}     # S ~ 40 Beta(2,2) + 80   [m]
      t:       {lo: -0.25, scale: 0.5}      # T ~ 0.5 Beta(2,2) - 0.25 [m]
      heading: {lo: -3.6,  scale: 7.2}      # W ~ 7.2 Beta(2,2) - 3.6  [deg]
      speed:   {lo: 10.0,  scale: 10.0}     # V ~ 10 Beta(2,2) + 10   [m/s]
    drivers:
      normal: {desired_speed: 25.0}         # IDM+MOBIL (model: idm_mobil)
      human: {model: learned}               # the learned driver network
    ego: {policy: idm_mobil, params: {desired_speed: 28.0}}
    vehicles:
      - {lane: 2, offset: 0.0}              # the ego
      - {lane: 2, offset: 50.0, driver: normal}
      - {lane: 3, offset: 20.0, driver: human}

Drivers, the ego policy and the safety measure are each a registered name or
an import path ``package.module:attribute`` to the user's own class, with its
parameters under ``params``, which the component checks when the scenario is
built (:mod:`avrisk.scenario.components`)::

    ego: {policy: "mypkg.egos:MyEgo", params: {gain: 0.8}}
    safety: {measure: min_ttc, n_rays: 360}

A scenario with any ``learned`` driver adds the network's last layer ``xi``
(one draw per rollout, shared by all its learned drivers) to the sample ``X``;
its ``learned_drivers`` section (:class:`LearnedDriversSpec`) says whether they
sample their actions, how far the cross-entropy method may move ``xi`` and
whether they change lanes
(:class:`~avrisk.scenario.components.LaneChangeSpec`; off when left out)::

    learned_drivers: {actions: mean, xi_search: 0.0, xi_search_unit: prior_sd,
                      lane_changes: {min_gap: 4.0}}

A vision ego (``ego: {policy: vision_pilotnet}``) sees the scene through a
front camera (:class:`~avrisk.scenario.sensors.CameraSpec`; its defaults when
left out), and a slot may give its vehicle's ``height`` [m] for it::

    camera: {width: 200, height: 66, hfov: 60.0, pitch: 5.0}

Unknown keys are rejected and every error names the field, the allowed range
and the value given. This module holds the whole scenario
(:class:`ScenarioSpec`, with the simulator settings); its parts are in
:mod:`avrisk.scenario.scene` (road, vehicle slots, initial conditions),
:mod:`avrisk.scenario.components` (drivers, ego, safety measure) and
:mod:`avrisk.scenario.sensors` (the ego camera of a vision ego);
:mod:`avrisk.scenario.loading` reads files (``yaml.safe_load``) and
:mod:`avrisk.scenario.errors` words the validation errors.
"""

from __future__ import annotations

import re
import warnings
from typing import Any

import yaml
from pydantic import (
    Field,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
    model_validator,
)

from avrisk.registry import is_import_path
from avrisk.scenario.components import (
    DriverSpec,
    EgoSpec,
    IDMSpec,
    LearnedDriversSpec,
    SafetySpec,
)
from avrisk.scenario.scene import (
    VEHICLE_FIELDS,
    InitialConditionsSpec,
    RoadSpec,
    SpecModel,
    VehicleSlotSpec,
)
from avrisk.scenario.sensors import CameraSpec

#: What a scenario's name (and a bundled scenario's file name) may be.
SCENARIO_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_\-]*$")

#: Time steps per rollout (``horizon / dt``) above which a scenario is refused,
#: and above which it is accepted with a warning. The bundled ones take 100.
MAX_STEPS = 100_000
WARN_STEPS = 10_000
#: Time steps per rollout of the bundled scenarios (10 s at 0.1 s), for costs.
_BUNDLED_STEPS = 100


class SimulationSpec(SpecModel):
    """Time discretisation and driver sensing."""

    dt: float = Field(0.1, gt=0, le=1.0, description="Time step [s].")
    horizon: float = Field(10.0, gt=0, le=600.0, description="Rollout length [s].")
    n_lidar_beams: int = Field(
        20, ge=1, le=1024, description="Lidar beams per driver [-]."
    )
    lidar_range: float = Field(
        50.0, gt=0, le=500.0, description="Lidar maximum range [m]."
    )

    @model_validator(mode="after")
    def _horizon_is_whole_steps(self) -> SimulationSpec:
        steps = self.horizon / self.dt
        if not steps <= MAX_STEPS:
            raise ValueError(
                f"horizon / dt = {self.horizon:g} s / {self.dt:g} s = "
                f"{steps:,.0f} time steps per rollout, more than the {MAX_STEPS:,} "
                f"allowed: each rollout would cost about {steps / _BUNDLED_STEPS:,.0f} "
                f"times one of the bundled scenarios ({_BUNDLED_STEPS} steps); use a "
                "larger dt or a shorter horizon"
            )
        if steps > WARN_STEPS:
            warnings.warn(
                f"horizon / dt = {steps:,.0f} time steps per rollout: each rollout "
                f"costs about {steps / _BUNDLED_STEPS:,.0f} times one of the bundled "
                f"scenarios ({_BUNDLED_STEPS} steps)",
                stacklevel=2,
            )
        if steps < 1 or abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
            raise ValueError(
                f"horizon ({self.horizon} s) must be a whole number (>= 1) of time "
                f"steps dt ({self.dt} s); e.g. horizon: "
                f"{max(1, round(steps)) * self.dt:g}"
            )
        return self

    @property
    def n_steps(self) -> int:
        """Number of time steps ``T = horizon / dt``."""
        return int(round(self.horizon / self.dt))


class ScenarioSpec(SpecModel):
    """A complete scenario: road, vehicles, base distribution, agents, simulator.

    Attributes
    ----------
    name : str
        Short identifier, used in file names and reports.
    vehicles : tuple of VehicleSlotSpec
        The ``A`` vehicle slots; slot 0 is the ego.
    """

    name: str = Field(description="Short identifier of the scenario.")
    description: str = Field("", max_length=10_000, description="Free text for people.")
    road: RoadSpec = Field(RoadSpec(), description="Road geometry.")
    initial_conditions: InitialConditionsSpec = Field(
        InitialConditionsSpec(),
        description="Marginals of every vehicle's initial condition (P0).",
    )
    drivers: dict[str, DriverSpec] = Field(
        default_factory=lambda: {"default": DriverSpec()},
        description="Environment driver types by name (heterogeneous traffic).",
    )
    ego: EgoSpec = Field(EgoSpec(), description="The ego policy under test.")
    vehicles: tuple[VehicleSlotSpec, ...] = Field(
        min_length=1, max_length=64, description="Vehicle slots; slot 0 is the ego."
    )
    simulation: SimulationSpec = Field(
        SimulationSpec(), description="Simulator settings."
    )
    safety: SafetySpec = Field(SafetySpec(), description="Safety measure settings.")
    learned_drivers: LearnedDriversSpec = Field(
        LearnedDriversSpec(),
        description="Actions and CE search box of the learned drivers (only "
        "with 'model: learned' driver types).",
    )
    camera: CameraSpec | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="The ego camera, for a vision ego; left out: the defaults "
        "(PilotNet's 66 x 200 image) when the ego reads a camera.",
    )

    @field_validator("name")
    @classmethod
    def _name_is_an_identifier(cls, v: str) -> str:
        if not SCENARIO_NAME.match(v) or len(v) > 100:
            raise ValueError(
                "must be 1-100 letters, digits, '_' or '-', starting with a "
                f"letter or digit; got {v!r}"
            )
        return v

    @model_validator(mode="after")
    def _slots_are_consistent(self) -> ScenarioSpec:
        problems = []
        n_lanes = self.road.n_lanes
        for j, slot in enumerate(self.vehicles):
            where = f"vehicles.{j}"
            if slot.lane >= n_lanes:
                problems.append(
                    f"{where}.lane: must be in [0, {n_lanes - 1}] (road.n_lanes = "
                    f"{n_lanes}); got {slot.lane}"
                )
            if j == 0 and slot.driver is not None:
                problems.append(
                    f"{where}.driver: slot 0 is the ego, driven by 'ego.policy'; "
                    f"remove driver: {slot.driver!r}"
                )
            if j > 0:
                if slot.driver is None and len(self.drivers) != 1:
                    problems.append(
                        f"{where}.driver: required when 'drivers' has "
                        f"{len(self.drivers)} types; choose one of "
                        f"{sorted(self.drivers)}"
                    )
                elif slot.driver is not None and slot.driver not in self.drivers:
                    problems.append(
                        f"{where}.driver: unknown driver type {slot.driver!r}; "
                        f"'drivers' defines {sorted(self.drivers)}"
                    )
        problems.extend(self._overlap_problems())
        if "learned_drivers" in self.model_fields_set and not self.has_learned_drivers:
            problems.append(
                "learned_drivers: set, but no vehicle has a 'model: learned' "
                "driver; remove the section or give a slot a learned driver type"
            )
        if problems:
            raise ValueError("\n".join(problems))
        return self

    def _overlap_problems(self) -> list[str]:
        """Slots in one lane whose start boxes could overlap at time 0."""
        problems = []
        for i in range(len(self.vehicles)):
            for j in range(i + 1, len(self.vehicles)):
                a, b = self.vehicles[i], self.vehicles[j]
                if a.lane != b.lane:
                    continue
                sa, sb = self.initial_for(i).s, self.initial_for(j).s
                # Centres range over [offset + lo, offset + lo + scale].
                lo_a, hi_a = a.offset + sa.lo, a.offset + sa.hi
                lo_b, hi_b = b.offset + sb.lo, b.offset + sb.hi
                gap = max(lo_b - hi_a, lo_a - hi_b)
                need = (a.length + b.length) / 2
                if gap < need:
                    problems.append(
                        f"vehicles.{i}, vehicles.{j}: both start in lane {a.lane} "
                        f"with centres in [{lo_a:g}, {hi_a:g}] m and "
                        f"[{lo_b:g}, {hi_b:g}] m, so they can start overlapping "
                        f"(centres must stay >= {need:g} m apart); change one "
                        "'offset' or 'lane'"
                    )
        return problems

    # ------------------------------------------------------------------ helpers
    @property
    def n_vehicles(self) -> int:
        """Number of vehicle slots ``A`` (ego included)."""
        return len(self.vehicles)

    def initial_for(self, slot: int) -> InitialConditionsSpec:
        """The marginals of slot ``slot`` after its overrides are applied.

        Parameters
        ----------
        slot : int
            Vehicle slot index, 0 = ego.

        Returns
        -------
        InitialConditionsSpec
        """
        base = self.initial_conditions
        over = self.vehicles[slot].initial
        if over is None:
            return base
        return InitialConditionsSpec(
            **{
                name: getattr(over, name) or getattr(base, name)
                for name in VEHICLE_FIELDS
            }
        )

    def driver_for(self, slot: int) -> IDMSpec:
        """The driver of slot ``slot``: its type, or the ego's IDM parameters.

        Parameters
        ----------
        slot : int
            Vehicle slot index, 0 = ego.

        Returns
        -------
        IDMSpec
            :attr:`EgoSpec.idm` for slot 0 (``ego.params`` of an idm_mobil
            ego, else the defaults), else the slot's :class:`DriverSpec`.
        """
        return self.ego.idm if slot == 0 else self.driver_type(slot)

    def driver_type(self, slot: int) -> DriverSpec:
        """The driver type of environment slot ``slot >= 1``."""
        name = self.vehicles[slot].driver
        if name is None:
            (name,) = self.drivers
        return self.drivers[name]

    @property
    def learned_slots(self) -> tuple[bool, ...]:
        """Per slot, whether the learned driver network drives it.

        Slot 0 is always False: the ego is driven by ``ego.policy``.
        """
        return (False,) + tuple(
            self.driver_type(j).learned for j in range(1, self.n_vehicles)
        )

    @property
    def has_learned_drivers(self) -> bool:
        """Whether any environment vehicle is a learned driver (``X`` has ``xi``)."""
        return any(self.learned_slots)

    @property
    def noise_dim(self) -> int:
        """Columns of the learned drivers' innovations in ``X``: ``2 T C``, or 0.

        ``T`` time steps, ``C`` learned drivers, two actions; 0 unless
        ``learned_drivers: {actions: sampled_in_x}``.
        """
        if not (self.has_learned_drivers and self.learned_drivers.noise_in_x):
            return 0
        return 2 * self.simulation.n_steps * sum(self.learned_slots)

    def import_paths(self) -> list[str]:
        """The components this spec names by import path, each once, in order.

        Building them imports user code, which avrisk does only for a spec
        given explicitly (:func:`avrisk.registry.load_component`); a spec read
        back from a run directory that names one must be given again.

        Returns
        -------
        list of str
            E.g. ``["mypkg.egos:MyEgo"]``: the ego policy, then the driver
            models in the order of ``drivers``, then the safety measure.
        """
        names = [
            self.ego.policy,
            *(driver.model for driver in self.drivers.values()),
            self.safety.measure,
        ]
        return list(dict.fromkeys(name for name in names if is_import_path(name)))

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """Dump without ``learned_drivers`` when no driver is learned."""
        data = handler(self)
        if not self.has_learned_drivers:
            data.pop("learned_drivers", None)
        return data

    def to_yaml(self) -> str:
        """The resolved spec as YAML text (loads back to an equal spec)."""
        return yaml.safe_dump(
            self.model_dump(mode="json"), sort_keys=False, default_flow_style=None
        )
