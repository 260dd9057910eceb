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

A scenario with any ``learned`` driver adds the network's last layer ``xi``
(one draw per rollout, shared by all its learned drivers) to the sample ``X``;
its ``learned_drivers`` section (:class:`LearnedDriversSpec`) says whether they
sample their actions and how far the cross-entropy method may move ``xi``::

    learned_drivers: {actions: mean, xi_search: 0.0, xi_search_unit: prior_sd}

Files are read with ``yaml.safe_load``; unknown keys are rejected and every
error names the field, the allowed range and the value given.
"""

from __future__ import annotations

import difflib
import math
import re
import types
import typing
from collections.abc import Iterable, Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    ValidationError,
    field_validator,
    model_serializer,
    model_validator,
)

#: Largest scenario file accepted [bytes]. Real specs are a few kB.
MAX_SPEC_BYTES = 1 << 20

#: Names of the per-vehicle initial-condition coordinates, in the order they
#: appear in a flat sample ``X`` (see :mod:`avrisk.scenario.params`).
VEHICLE_FIELDS: tuple[str, ...] = ("s", "t", "heading", "speed")

_BUNDLED_PACKAGE = "avrisk"
_BUNDLED_DIR = ("data", "scenarios")
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_\-]*$")


class ScenarioSpecError(ValueError):
    """A scenario file could not be found, read or validated.

    The message is meant for a person: it names the file, each bad field, the
    allowed values and what was given.
    """


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)


PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class RoadSpec(_Model):
    """Road geometry: a straight (or constant-curvature) multi-lane highway.

    Lane 0 is the rightmost lane; the lateral coordinate grows to the left.
    The defaults are the NGSIM I-80 study area (Emeryville, CA).
    """

    n_lanes: int = Field(6, ge=1, le=12, description="Number of lanes [-].")
    lane_width: float = Field(
        3.7, ge=2.5, le=5.0, description="Width of every lane [m]."
    )
    length: float = Field(
        500.0, ge=50.0, le=20_000.0, description="Length of the road [m]."
    )
    curvature: float = Field(
        0.0,
        description="Curvature of the lane centre lines [1/m]; only 0 (straight) "
        "is simulated for now.",
    )

    @field_validator("curvature")
    @classmethod
    def _straight_only(cls, v: float) -> float:
        if v != 0.0:
            raise ValueError(
                f"only straight roads (curvature: 0.0) are simulated for now; got {v}"
            )
        return v

    @property
    def width(self) -> float:
        """Total road width ``n_lanes * lane_width`` [m]."""
        return self.n_lanes * self.lane_width


class MarginalSpec(_Model):
    """One scaled-Beta marginal ``lo + scale * Beta(a, b)`` and its CE search box.

    The cross-entropy method searches over ``Beta(a', b')`` with ``a', b'`` in
    ``search`` (paper: ``[1.5, 7]``), keeping ``lo`` and ``scale`` fixed. The
    likelihood ratio ``Beta(a, b) / Beta(a', b')`` has finite variance under
    the proposal only while ``a' < 2 a`` and ``b' < 2 b``; a box reaching
    further lets CE pick proposals whose estimates are unreliable (too low,
    with too small a standard error).
    """

    lo: float = Field(
        description="Lower end of the support, in the unit of the coordinate.",
        allow_inf_nan=False,
    )
    scale: PositiveFloat = Field(
        description="Width of the support, in the unit of the coordinate."
    )
    a: float = Field(2.0, gt=0, le=1000, description="First Beta shape [-].")
    b: float = Field(2.0, gt=0, le=1000, description="Second Beta shape [-].")
    search: tuple[float, float] = Field(
        (1.5, 7.0),
        description="CE search box [low, high] for both shapes a and b [-].",
    )

    @field_validator("search")
    @classmethod
    def _search_is_an_interval(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (0 < lo < hi < math.inf):
            raise ValueError(
                f"must be [low, high] with 0 < low < high < inf; got {list(v)}"
            )
        return v

    @model_validator(mode="after")
    def _base_lies_in_search_box(self) -> MarginalSpec:
        lo, hi = self.search
        if not (lo <= self.a <= hi and lo <= self.b <= hi):
            raise ValueError(
                f"the base shapes a={self.a}, b={self.b} must lie inside the "
                f"search box {list(self.search)}, or the cross-entropy method "
                "cannot represent P0; widen 'search' or change a, b"
            )
        return self

    @property
    def hi(self) -> float:
        """Upper end of the support ``lo + scale``."""
        return self.lo + self.scale

    @property
    def mean(self) -> float:
        """Exact mean ``lo + scale * a / (a + b)``."""
        return self.lo + self.scale * self.a / (self.a + self.b)

    @property
    def variance(self) -> float:
        """Exact variance ``scale^2 a b / ((a+b)^2 (a+b+1))``."""
        ab = self.a + self.b
        return self.scale**2 * self.a * self.b / (ab * ab * (ab + 1.0))


class InitialConditionsSpec(_Model):
    """Marginals of one vehicle's initial condition relative to its slot.

    Paper's values (the defaults): ``S ~ 40 Beta(2,2) + 80`` m,
    ``T ~ 0.5 Beta(2,2) - 0.25`` m, ``W ~ 7.2 Beta(2,2) - 3.6`` deg,
    ``V ~ 10 Beta(2,2) + 10`` m/s.
    """

    s: MarginalSpec = Field(
        MarginalSpec(lo=80.0, scale=40.0),
        description="Position along the road, added to the slot offset [m].",
    )
    t: MarginalSpec = Field(
        MarginalSpec(lo=-0.25, scale=0.5),
        description="Lateral offset from the lane centre, positive left [m].",
    )
    heading: MarginalSpec = Field(
        MarginalSpec(lo=-3.6, scale=7.2),
        description="Heading relative to the lane direction, ccw positive [deg].",
    )
    speed: MarginalSpec = Field(
        MarginalSpec(lo=10.0, scale=10.0), description="Initial speed [m/s]."
    )

    @model_validator(mode="after")
    def _physical_ranges(self) -> InitialConditionsSpec:
        if self.heading.lo < -45.0 or self.heading.hi > 45.0:
            raise ValueError(
                f"heading support [{self.heading.lo}, {self.heading.hi}] deg must "
                "lie within [-45, 45] deg of the lane direction"
            )
        if self.speed.lo < 0.0:
            raise ValueError(
                f"speed support must start at >= 0 m/s; got lo={self.speed.lo}"
            )
        return self


class InitialConditionsOverride(_Model):
    """Per-slot replacement of some of the shared marginals (others inherited)."""

    s: MarginalSpec | None = Field(None, description="See InitialConditionsSpec.s.")
    t: MarginalSpec | None = Field(None, description="See InitialConditionsSpec.t.")
    heading: MarginalSpec | None = Field(
        None, description="See InitialConditionsSpec.heading."
    )
    speed: MarginalSpec | None = Field(
        None, description="See InitialConditionsSpec.speed."
    )


class IDMSpec(_Model):
    """Intelligent Driver Model (car following) + MOBIL (lane changes).

    Defaults are typical highway values (Treiber and Kesting, *Traffic Flow
    Dynamics*, 2013; HighwayEnv's ``IDMVehicle``).
    """

    desired_speed: float = Field(
        30.0, gt=0, le=60.0, description="Free-road target speed [m/s]."
    )
    time_headway: float = Field(
        1.5, gt=0, le=5.0, description="Desired time gap to the leader [s]."
    )
    min_gap: float = Field(
        2.0, ge=0, le=20.0, description="Jam distance to the leader [m]."
    )
    max_accel: float = Field(
        1.5, gt=0, le=10.0, description="Maximum acceleration [m/s^2]."
    )
    comfort_decel: float = Field(
        2.0, gt=0, le=10.0, description="Comfortable deceleration [m/s^2]."
    )
    politeness: float = Field(
        0.3, ge=0, le=1.0, description="MOBIL politeness factor [-]."
    )
    lane_change_threshold: float = Field(
        0.2,
        ge=0,
        le=5.0,
        description="MOBIL acceleration gain needed to change lane [m/s^2].",
    )


#: The choice (driver model, ego policy) that takes IDM+MOBIL parameters.
IDM_MOBIL = "idm_mobil"


def _refuse_idm_fields(spec: BaseModel, selector: str, fields: Iterable[str]) -> None:
    """Reject IDM+MOBIL parameters given with a ``selector`` other than idm_mobil."""
    choice = getattr(spec, selector)
    given = sorted(spec.model_fields_set & set(fields))
    if choice != IDM_MOBIL and given:
        raise ValueError(
            f"{selector} {choice!r} takes no IDM+MOBIL parameters; remove "
            f"{', '.join(given)}"
        )


def _without_idm_fields(
    spec: BaseModel, selector: str, fields: Iterable[str], data: dict[str, Any]
) -> dict[str, Any]:
    """``data`` (a dump of ``spec``) without the unused IDM+MOBIL parameters."""
    if getattr(spec, selector) == IDM_MOBIL:
        return data
    return {k: v for k, v in data.items() if k not in set(fields)}


class DriverSpec(IDMSpec):
    """An environment driver type: a driver model and its parameters.

    ``model: idm_mobil`` drives with IDM+MOBIL and the parameters of
    :class:`IDMSpec`. ``model: learned`` drives with the shipped driver network
    (:mod:`avrisk.agents.drivers`, imitation-learned from NGSIM) and takes no
    parameters: its last layer ``xi`` is part of the random sample ``X``, one
    draw per rollout shared by every learned driver of the rollout. IDM+MOBIL
    neighbours predict a learned driver's reactions (MOBIL) with the
    :class:`IDMSpec` defaults.
    """

    model: Literal["idm_mobil", "learned"] = Field(
        IDM_MOBIL,
        description="Driver model: 'idm_mobil' (IDM car following + MOBIL lane "
        "changes) or 'learned' (the imitation-learned driver network).",
    )

    @model_validator(mode="after")
    def _idm_fields_for_idm_only(self) -> DriverSpec:
        _refuse_idm_fields(self, "model", IDMSpec.model_fields)
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        return _without_idm_fields(self, "model", IDMSpec.model_fields, handler(self))

    @property
    def learned(self) -> bool:
        """Whether the driver network drives (``model: learned``)."""
        return self.model == "learned"


class EgoSpec(_Model):
    """The ego policy under test (vehicle slot 0).

    ``idm_mobil`` drives with IDM+MOBIL and ``params``; ``lidar_imitation`` is
    the paper's non-vision ego, the shipped driver network on the ego's own
    lidar and lane features with its trained shared last layer and its mean
    action (:class:`avrisk.agents.drivers.LearnedEgoPolicy`), and takes no
    ``params``.
    """

    policy: Literal["idm_mobil", "lidar_imitation"] = Field(
        IDM_MOBIL,
        description="Ego policy: 'idm_mobil' (IDM+MOBIL with 'params') or "
        "'lidar_imitation' (the learned lidar-based imitation policy).",
    )
    params: IDMSpec = Field(
        IDMSpec(), description="Parameters of the idm_mobil ego policy."
    )

    @model_validator(mode="after")
    def _params_for_idm_only(self) -> EgoSpec:
        _refuse_idm_fields(self, "policy", ("params",))
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        return _without_idm_fields(self, "policy", ("params",), handler(self))


class VehicleSlotSpec(_Model):
    """Where one vehicle starts and what it is.

    The vehicle's initial position along the road is ``offset + S`` [m] and its
    lateral position is the centre of ``lane`` plus ``T`` [m].
    """

    lane: int = Field(ge=0, description="Lane index, 0 = rightmost [-].")
    offset: float = Field(
        0.0,
        ge=-10_000.0,
        le=10_000.0,
        description="Longitudinal offset added to S [m].",
    )
    length: float = Field(4.8, gt=1.0, le=25.0, description="Vehicle length [m].")
    width: float = Field(1.9, gt=0.5, le=3.5, description="Vehicle width [m].")
    driver: str | None = Field(
        None,
        description="Name of a driver type in 'drivers'; must be unset for the ego.",
    )
    initial: InitialConditionsOverride | None = Field(
        None, description="Per-slot replacement of the shared marginals."
    )


class SimulationSpec(_Model):
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


class SafetySpec(_Model):
    """The safety measure ``f``: minimum time-to-collision [s] over the rollout.

    ``min_ttc`` is the paper's ray TTC from the ego centre (appendix A);
    ``min_box_ttc`` the exact constant-velocity TTC between the vehicle
    rectangles, which does not count vehicles sliding past parallel in the next
    lane as near-collisions (see :mod:`avrisk.safety.box_ttc`).
    """

    measure: Literal["min_ttc", "min_box_ttc"] = Field(
        "min_ttc",
        description="Safety measure: 'min_ttc' (ray TTC, paper appendix A) or "
        "'min_box_ttc' (exact TTC between the vehicle rectangles).",
    )
    n_rays: int = Field(
        360,
        ge=4,
        le=4096,
        description="Rays cast from the ego centre [-] (min_ttc only).",
    )


class LearnedDriversSpec(_Model):
    """How the learned environment drivers act and how CE may tilt their ``xi``.

    ``actions: sampled`` draws every action from the network's Gaussians with
    per-rollout noise (the paper's generative model); the noise is not part of
    ``X``, so importance sampling cannot steer it and ``f(X)`` stays random
    given ``X``. ``actions: mean`` drives with the mean actions: the drivers'
    randomness is then all in ``X`` (the per-rollout ``xi``, the ensemble's
    uncertainty about the policy) and ``f(X)`` is a deterministic function of
    ``X``.

    ``xi_search`` is the half-width of the cross-entropy search box for the
    mean of ``xi`` around ``mu0``, per coordinate: in the units of ``xi``
    (``xi_search_unit: absolute``; the paper's 0.01) or in prior standard
    deviations ``sqrt(diag Sigma0)`` (``prior_sd``), which treats every
    coordinate alike whatever its spread. 0 keeps ``xi ~ P0`` (CE does not
    tilt it; its likelihood ratio is 1).
    """

    actions: Literal["sampled", "mean"] = Field(
        "sampled",
        description="'sampled' (the paper: actions drawn from the network's "
        "Gaussians) or 'mean' (the mean actions; f deterministic given X).",
    )
    xi_search: float = Field(
        0.01,
        ge=0.0,
        le=100.0,
        description="Half-width of the CE search box for the mean of xi, per "
        "coordinate, in xi_search_unit (paper: 0.01 absolute).",
    )
    xi_search_unit: Literal["absolute", "prior_sd"] = Field(
        "absolute",
        description="Unit of xi_search: 'absolute' (units of xi) or 'prior_sd' "
        "(prior standard deviations of each coordinate).",
    )

    @property
    def stochastic(self) -> bool:
        """Whether actions are sampled (``actions: sampled``)."""
        return self.actions == "sampled"


class ScenarioSpec(_Model):
    """A complete scenario: road, vehicles, base distribution, agents, simulator.

    Attributes
    ----------
    name : str
        Short identifier, used in file names and reports.
    vehicles : tuple of VehicleSlotSpec
        The ``A`` vehicle slots; slot 0 is the ego.
    """

    name: str = Field(description="Short identifier of the scenario.")
    description: str = Field("", description="Free text for people.")
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

    @field_validator("name")
    @classmethod
    def _name_is_an_identifier(cls, v: str) -> str:
        if not _NAME_RE.match(v) or len(v) > 100:
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
            ``ego.params`` for slot 0, else the slot's :class:`DriverSpec`.
        """
        return self.ego.params if slot == 0 else self._driver_type(slot)

    def _driver_type(self, slot: int) -> DriverSpec:
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
            self._driver_type(j).learned for j in range(1, self.n_vehicles)
        )

    @property
    def has_learned_drivers(self) -> bool:
        """Whether any environment vehicle is a learned driver (``X`` has ``xi``)."""
        return any(self.learned_slots)

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


# --------------------------------------------------------------------- loading
def bundled_scenarios() -> list[str]:
    """Names of the scenarios shipped with avrisk (usable by name in the CLI).

    Returns
    -------
    list of str
        Sorted names, e.g. ``["highway_default"]``.
    """
    folder = resources.files(_BUNDLED_PACKAGE).joinpath(*_BUNDLED_DIR)
    return sorted(
        p.name.removesuffix(".yaml")
        for p in folder.iterdir()
        if p.name.endswith(".yaml")
    )


def load_spec(path_or_name: str | Path) -> ScenarioSpec:
    """Read and validate a scenario from a YAML file or a bundled name.

    Parameters
    ----------
    path_or_name : str or pathlib.Path
        A path to a ``.yaml`` file, or the name of a bundled scenario (see
        :func:`bundled_scenarios`), e.g. ``"highway_default"``.

    Returns
    -------
    ScenarioSpec

    Raises
    ------
    ScenarioSpecError
        If the file does not exist, is larger than ``MAX_SPEC_BYTES``, is not
        YAML, or does not validate; the message names each bad field.

    Examples
    --------
    >>> spec = load_spec("highway_default")
    >>> spec.road.n_lanes, spec.n_vehicles
    (6, 6)
    """
    text, source = _read_source(path_or_name)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ScenarioSpecError(f"{source}: not valid YAML: {exc}") from None
    return spec_from_dict(data, source=source)


def spec_from_dict(data: Any, *, source: str = "<dict>") -> ScenarioSpec:
    """Validate an already-parsed mapping into a :class:`ScenarioSpec`.

    Parameters
    ----------
    data : mapping
        The parsed YAML document.
    source : str, default="<dict>"
        Where the data came from, for error messages.

    Returns
    -------
    ScenarioSpec

    Raises
    ------
    ScenarioSpecError
        If the mapping does not validate.
    """
    if not isinstance(data, Mapping):
        raise ScenarioSpecError(
            f"{source}: the top level must be a mapping of fields (road, "
            f"vehicles, ...); got {type(data).__name__}"
        )
    try:
        return ScenarioSpec.model_validate(dict(data))
    except ValidationError as exc:
        raise ScenarioSpecError(format_validation_error(exc, source)) from None


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line per problem: ``field.path: what is wrong (got value)``.

    Parameters
    ----------
    exc : pydantic.ValidationError
    source : str
        The file or name being validated.

    Returns
    -------
    str
    """
    lines = [f"{source}: invalid scenario:"]
    for err in exc.errors(include_url=False):
        loc = ".".join(str(p) for p in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = _unknown_field_message(err["loc"])
        elif err["type"] == "missing":
            msg = "required field is missing"
        got = err.get("input")
        show_got = err["type"] not in {"missing", "value_error", "assertion_error"}
        if show_got and not isinstance(got, Mapping | list):
            msg = f"{msg} (got {got!r})"
        if not loc:
            # Cross-field problems name their own fields, one per line.
            lines.extend(f"  {line}" for line in msg.splitlines())
        else:
            lines.append(f"  {loc}: {msg}")
    return "\n".join(lines)


def _unknown_field_message(loc: tuple[int | str, ...]) -> str:
    """Explain an unknown key, suggesting the closest allowed field names."""
    model: Any = ScenarioSpec
    for part in loc[:-1]:
        model = _field_type(model, part)
    models = [m for m in _union_members(model) if _is_model(m)]
    allowed = sorted(models[0].model_fields) if models else []
    close = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown field; {hint}allowed here: {', '.join(allowed)}"


def _is_model(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _union_members(tp: Any) -> tuple[Any, ...]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return typing.get_args(tp)
    return (tp,)


def _field_type(tp: Any, part: int | str) -> Any:
    """Type reached from ``tp`` by one step of a validation-error location."""
    # Unwrap Optional[...] / X | None to the model inside.
    for arg in _union_members(tp):
        if _is_model(arg) and isinstance(part, str) and part in arg.model_fields:
            return arg.model_fields[part].annotation
        origin = typing.get_origin(arg)
        if origin in (tuple, list) and isinstance(part, int):
            return typing.get_args(arg)[0]
        if origin is dict and isinstance(part, str):
            return typing.get_args(arg)[1]
    return None


def _read_source(path_or_name: str | Path) -> tuple[str, str]:
    """Return the text of a spec file or bundled scenario and its display name."""
    path = Path(path_or_name)
    if path.is_file():
        size = path.stat().st_size
        if size > MAX_SPEC_BYTES:
            raise ScenarioSpecError(
                f"{path}: {size} bytes is larger than the {MAX_SPEC_BYTES}-byte "
                "limit for a scenario file; is this the right file?"
            )
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except (OSError, UnicodeDecodeError) as exc:
            raise ScenarioSpecError(f"{path}: cannot be read: {exc}") from None
    name = str(path_or_name)
    if _NAME_RE.match(name) and name in bundled_scenarios():
        res = resources.files(_BUNDLED_PACKAGE).joinpath(*_BUNDLED_DIR, name + ".yaml")
        return res.read_text(encoding="utf-8"), f"{name} (bundled)"
    raise ScenarioSpecError(
        f"no scenario file {str(path_or_name)!r} and no bundled scenario of that "
        f"name; give a path to a .yaml file or one of {bundled_scenarios()}"
    )
