"""The scene of a scenario: the road, the vehicle slots and their initial conditions.

These models describe the world at time 0 and the base distribution ``P0`` of
the initial conditions relative to each slot (paper, Sec. 5: ``S, T, W, V``);
:class:`SpecModel` is the base of every model of a scenario spec.
"""

from __future__ import annotations

import math
import types
import typing
from typing import Annotated, Any

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

#: Names of the per-vehicle initial-condition coordinates, in the order they
#: appear in a flat sample ``X`` (see :mod:`avrisk.scenario.params`).
VEHICLE_FIELDS: tuple[str, ...] = ("s", "t", "heading", "speed")


class SpecModel(BaseModel):
    """Base of the scenario spec's models: frozen, unknown keys rejected.

    A number field takes no boolean (YAML's ``yes``, ``on``, ``true``, which
    Pydantic would read as 1); text that reads as a number stays accepted
    (YAML reads ``1e-3``, without a dot, as text).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)

    @field_validator("*", mode="before")
    @classmethod
    def _numbers_are_numbers(cls, value: Any, info: ValidationInfo) -> Any:
        if info.field_name is None:
            return value
        kind = _number_kind(cls.model_fields[info.field_name].annotation)
        if kind == "number":
            _check_number(value)
        elif kind == "numbers" and isinstance(value, list | tuple):
            for item in value:
                _check_number(item)
        return value


def _number_kind(annotation: Any) -> str | None:
    """``"number"``: an int or float field; ``"numbers"``: a tuple of them."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        kinds = {_number_kind(a) for a in args if a is not type(None)}
        return kinds.pop() if len(kinds) == 1 else None
    if annotation in (int, float):
        return "number"
    if typing.get_origin(annotation) is tuple and args:
        if all(a in (int, float, Ellipsis) for a in args):
            return "numbers"
    return None


def _check_number(value: Any) -> None:
    if isinstance(value, bool):
        raise ValueError(f"must be a number, not a boolean ({str(value).lower()})")


PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class RoadSpec(SpecModel):
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


class MarginalSpec(SpecModel):
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


class InitialConditionsSpec(SpecModel):
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


class InitialConditionsOverride(SpecModel):
    """Per-slot replacement of some of the shared marginals (others inherited)."""

    s: MarginalSpec | None = Field(None, description="See InitialConditionsSpec.s.")
    t: MarginalSpec | None = Field(None, description="See InitialConditionsSpec.t.")
    heading: MarginalSpec | None = Field(
        None, description="See InitialConditionsSpec.heading."
    )
    speed: MarginalSpec | None = Field(
        None, description="See InitialConditionsSpec.speed."
    )


class VehicleSlotSpec(SpecModel):
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
    height: float | None = Field(
        None,
        gt=0.3,
        le=6.0,
        exclude_if=lambda v: v is None,
        description="Vehicle height, for the ego camera [m]; left out: 1.5.",
    )
    driver: str | None = Field(
        None,
        description="Name of a driver type in 'drivers'; must be unset for the ego.",
    )
    initial: InitialConditionsOverride | None = Field(
        None, description="Per-slot replacement of the shared marginals."
    )
