"""A scenario's components: environment drivers, ego policy, safety measure.

Each is chosen by name, with its parameters under ``params``::

    drivers:
      normal: {desired_speed: 25.0}               # IDM+MOBIL (model: idm_mobil)
      human: {model: learned}                     # the learned driver network
    ego: {policy: constant, params: {accel: 0.5}}
    safety: {measure: "mypkg.measures:MinGap", params: {margin: 1.0}}

A name is a registered one (``[a-z_][a-z0-9_]*``: ``lidar_imitation``,
``min_box_ttc``, ...) or an import path ``package.module:attribute`` to the
user's own class or factory. The scenario is pure data: it checks the form of
names and that ``params`` are JSON-able (:data:`ComponentName`,
:data:`ComponentParams`); whether a name exists and its params are right is
checked by the component itself when the scenario is built
(:meth:`avrisk.registry.Registry.build`). Two names are built by the
scenario itself, and their parameters checked here: ``idm_mobil`` (IDM+MOBIL,
:class:`IDMSpec`; as a driver its parameters sit beside ``model``, as the ego
under ``params``) and the driver model ``learned`` (no parameters; its
settings are :class:`LearnedDriversSpec`).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    Field,
    JsonValue,
    SerializerFunctionWrapHandler,
    TypeAdapter,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)

from avrisk.registry import check_component_name
from avrisk.scenario.scene import SpecModel

#: A component chosen by name: a registered name or an import path
#: ``package.module:attribute`` (form checked here, existence when built).
ComponentName = Annotated[str, AfterValidator(check_component_name)]

#: A component's own parameters: JSON-able values, validated by the
#: component when the scenario is built.
ComponentParams = dict[str, JsonValue]

_COMPONENT_PARAMS: TypeAdapter[ComponentParams] = TypeAdapter(ComponentParams)

#: The driver model and ego policy run as IDM+MOBIL, with :class:`IDMSpec`.
IDM_MOBIL = "idm_mobil"

#: The driver model run by the shipped driver network (its ``xi`` is in ``X``).
LEARNED = "learned"


def _no_params(params: Any) -> bool:
    """Whether ``params`` is empty: then the dump leaves it out, as it reads.

    A spec that gives no ``params`` thus dumps (to a run's ``config.json``)
    exactly as it did before components took ``params``.
    """
    return params == {}


class IDMSpec(SpecModel):
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


class DriverSpec(IDMSpec):
    """An environment driver type: a driver model and its parameters.

    ``model: idm_mobil`` (the default) drives with IDM+MOBIL and the
    parameters of :class:`IDMSpec`, given beside ``model``. ``model: learned``
    drives with the shipped driver network (:mod:`avrisk.agents.drivers`,
    imitation-learned from NGSIM) and takes no parameters: its last layer
    ``xi`` is part of the random sample ``X``, one draw per rollout shared by
    every learned driver of the rollout. IDM+MOBIL neighbours predict a
    non-IDM driver's reactions (MOBIL) with the :class:`IDMSpec` defaults. Any
    other model (a registered name or an import path) takes ``params``.
    """

    model: ComponentName = Field(
        IDM_MOBIL,
        description="Driver model: 'idm_mobil' (IDM car following + MOBIL lane "
        "changes), 'learned' (the imitation-learned driver network), another "
        "registered name or an import path 'package.module:attribute'.",
    )
    params: ComponentParams = Field(
        default_factory=dict,
        exclude_if=_no_params,
        description="Parameters of a driver model other than idm_mobil and "
        "learned, validated by the model.",
    )

    @model_validator(mode="after")
    def _parameters_fit_the_model(self) -> DriverSpec:
        idm_given = sorted(self.model_fields_set & IDMSpec.model_fields.keys())
        if self.model != IDM_MOBIL and idm_given:
            raise ValueError(
                f"model {self.model!r} takes no IDM+MOBIL parameters; remove "
                f"{', '.join(idm_given)}"
            )
        if self.params and self.model == IDM_MOBIL:
            raise ValueError(
                "model 'idm_mobil' takes its parameters beside 'model' (e.g. "
                "{model: idm_mobil, desired_speed: 25.0}), not under 'params'"
            )
        if self.params and self.learned:
            raise ValueError(
                "model 'learned' takes no params; the learned drivers' settings "
                "are the scenario's 'learned_drivers' section"
            )
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """Dump without the IDM+MOBIL parameters unless the model uses them."""
        data = handler(self)
        if self.model == IDM_MOBIL:
            return data
        return {k: v for k, v in data.items() if k not in IDMSpec.model_fields}

    @property
    def learned(self) -> bool:
        """Whether the driver network drives (``model: learned``)."""
        return self.model == LEARNED


class EgoSpec(SpecModel):
    """The ego policy under test (vehicle slot 0) and its ``params``.

    ``idm_mobil`` (the default) drives with IDM+MOBIL, ``params`` being
    :class:`IDMSpec`. Any other policy is a registered name or an import path
    and validates its own ``params`` when the scenario is built:
    ``lidar_imitation``, the paper's non-vision ego (the shipped driver
    network on the ego's own lidar and lane features, with its trained shared
    last layer and its mean action; :class:`avrisk.agents.drivers.LearnedEgoPolicy`),
    takes ``range_scale`` (a miscalibrated lidar, for a variant to compare;
    default 1); ``constant`` takes ``accel`` and ``steer``.
    """

    policy: ComponentName = Field(
        IDM_MOBIL,
        description="Ego policy: 'idm_mobil' (IDM+MOBIL), 'lidar_imitation' (the "
        "learned lidar-based imitation policy), another registered name or an "
        "import path 'package.module:attribute'.",
    )
    params: IDMSpec | ComponentParams = Field(
        default_factory=dict,
        exclude_if=_no_params,
        description="Parameters of the ego policy (IDM+MOBIL's for idm_mobil).",
    )

    @field_validator("params", mode="plain")
    @classmethod
    def _params_of_the_policy(
        cls, value: Any, info: ValidationInfo
    ) -> IDMSpec | ComponentParams:
        if info.data.get("policy") == IDM_MOBIL:
            return IDMSpec.model_validate(value)
        return _COMPONENT_PARAMS.validate_python(value)

    @property
    def idm(self) -> IDMSpec:
        """The ego's IDM+MOBIL parameters: ``params`` of an idm_mobil ego.

        Any other ego gets the :class:`IDMSpec` defaults, with which IDM+MOBIL
        neighbours predict its reactions (MOBIL).
        """
        return self.params if isinstance(self.params, IDMSpec) else IDMSpec()


class SafetySpec(SpecModel):
    """The safety measure ``f`` (low means dangerous) and its ``params``.

    Registered: ``min_ttc``, the paper's minimum ray time-to-collision [s]
    from the ego centre (appendix A), with ``n_rays`` rays; ``min_box_ttc``,
    the exact constant-velocity TTC between the vehicle rectangles, which does
    not count vehicles sliding past parallel in the next lane as
    near-collisions (see :mod:`avrisk.safety.box_ttc`). Neither takes
    ``params``; a measure named by import path may.
    """

    measure: ComponentName = Field(
        "min_ttc",
        description="Safety measure: 'min_ttc' (ray TTC, paper appendix A), "
        "'min_box_ttc' (exact TTC between the vehicle rectangles), another "
        "registered name or an import path 'package.module:attribute'.",
    )
    params: ComponentParams = Field(
        default_factory=dict,
        exclude_if=_no_params,
        description="Parameters of the measure, validated by the measure.",
    )
    n_rays: int = Field(
        360,
        ge=4,
        le=4096,
        description="Rays cast from the ego centre [-] (min_ttc only).",
    )


def _is_none(value: Any) -> bool:
    """Whether an optional setting was left out (the dump then leaves it out)."""
    return value is None


def _unset_field(description: str, **bounds: float) -> Any:
    """An optional number: None (left out of the dump) takes the model's default."""
    return Field(None, exclude_if=_is_none, description=description, **bounds)


class LaneChangeSpec(SpecModel):
    """Lane changes of the learned drivers (:mod:`avrisk.agents.drivers.lane_change`).

    A desire to change arrives at a constant hazard ``rate``; it is carried out
    once the target lane's vehicles ahead and behind leave at least
    ``min_gap`` and ``min_ttc``, or lapses after ``patience``; the driver
    network then steers to the target lane, seeing at most ``offset_clip`` of
    offset. A setting left out takes the driver's default
    (:class:`~avrisk.agents.drivers.lane_change.LaneChangeParams`: the rate
    fitted in closed loop to the US-101 training vehicles, the gap thresholds
    chosen in closed loop for the fewest lane-change collisions that keep the
    rate; BENCHMARKS.md, "Lane changes of the learned drivers").
    """

    rate_per_hour: float | None = _unset_field(
        "Hazard of a lane-change desire [1/vehicle-h].", ge=0.0, le=3600.0
    )
    min_gap: float | None = _unset_field(
        "Least bumper gap to the target lane's vehicles ahead and behind [m].",
        ge=0.0,
        le=100.0,
    )
    min_ttc: float | None = _unset_field(
        "Least time-to-collision with them, when closing [s].", ge=0.0, le=60.0
    )
    patience: float | None = _unset_field(
        "A desire not carried out within this long lapses [s].", ge=0.0, le=600.0
    )
    offset_clip: float | None = _unset_field(
        "Largest offset from the target lane's centre the network sees [m].",
        gt=0.0,
        le=10.0,
    )

    def settings(self) -> dict[str, float]:
        """The settings given, in the driver's units (``rate`` [1/s])."""
        given = self.model_dump(exclude_none=True)
        if "rate_per_hour" in given:
            given["rate"] = given.pop("rate_per_hour") / 3600.0
        return given


class LearnedDriversSpec(SpecModel):
    """How the learned environment drivers act and how CE may tilt their ``xi``.

    ``actions: sampled`` draws every action from the network's Gaussians with
    per-rollout noise (the paper's generative model); the noise is not part of
    ``X``, so importance sampling cannot steer it and ``f(X)`` stays random
    given ``X``. ``actions: sampled_in_x`` samples the same way, but the
    innovations are columns of ``X`` (``noise.K``: one standard normal per
    learned driver, step and action, ``2 T C`` in all, independent under
    ``P0``): ``f(X)`` is then a deterministic function of ``X`` and
    estimators can steer the noise (``splitting_is`` tilts it like any
    coordinate; the cross-entropy method leaves it at ``P0``, as a mean
    update in that many dimensions is noise). ``actions: mean`` drives with
    the mean actions: the drivers' randomness is then all in ``xi`` (the
    per-rollout draw, the ensemble's uncertainty about the policy).

    ``xi_search`` is the half-width of the cross-entropy search box for the
    mean of ``xi`` around ``mu0``, per coordinate: in the units of ``xi``
    (``xi_search_unit: absolute``; the paper's 0.01) or in prior standard
    deviations ``sqrt(diag Sigma0)`` (``prior_sd``), which treats every
    coordinate alike whatever its spread. 0 keeps ``xi ~ P0`` (CE does not
    tilt it; its likelihood ratio is 1).

    ``lane_changes`` (:class:`LaneChangeSpec`) lets them change lanes; left
    out, they keep their lanes (and the spec dumps as before the option).
    """

    actions: Literal["sampled", "sampled_in_x", "mean"] = Field(
        "sampled",
        description="'sampled' (the paper: actions drawn from the network's "
        "Gaussians, noise from the rollout's seed), 'sampled_in_x' (the same, "
        "the noise's innovations columns of X) or 'mean' (the mean actions); f "
        "is deterministic given X except with 'sampled'.",
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
    lane_changes: LaneChangeSpec | None = Field(
        None,
        exclude_if=_is_none,
        description="Lane changes of the learned drivers; left out: they keep "
        "their lanes ({} turns them on with the defaults).",
    )

    @property
    def stochastic(self) -> bool:
        """Whether actions are sampled (``sampled`` or ``sampled_in_x``)."""
        return self.actions != "mean"

    @property
    def noise_in_x(self) -> bool:
        """Whether the action noise's innovations are columns of ``X``."""
        return self.actions == "sampled_in_x"
