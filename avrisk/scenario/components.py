"""A scenario's components: environment drivers, ego policy, safety measure.

Each is chosen by name; the learned drivers' settings are in
:class:`LearnedDriversSpec`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Literal

from pydantic import (
    BaseModel,
    Field,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from avrisk.scenario.scene import SpecModel


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


class EgoSpec(SpecModel):
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


class SafetySpec(SpecModel):
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


class LearnedDriversSpec(SpecModel):
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
