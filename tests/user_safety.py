"""A user's own safety measure, in one module, named by import path in a scenario.

``safety: {measure: "tests.user_safety:MinCentreDistance", params: {cap: 40}}``:
``f`` is the smallest distance [m] between the ego's centre and another
vehicle's over the rollout, capped at ``cap``. It implements
:class:`avrisk.sim.interfaces.SafetyMeasure`: a value per instant, folded
into a running minimum while the rollout is alive.
"""

import torch
from pydantic import BaseModel, Field
from torch import Tensor

from avrisk.sim.state import VehicleState


class MinCentreDistance:
    """``f`` = min over time of the ego's centre distance to the nearest other [m]."""

    class Params(BaseModel):
        """What ``params`` may set."""

        cap: float = Field(100.0, gt=0.0, description="Largest distance counted [m].")

    name = "min_centre_distance"
    tests_per_pair = 1

    def __init__(self, cap: float = 100.0) -> None:
        self.cap = cap

    def instant(
        self, state: VehicleState, cos: Tensor | None = None, sin: Tensor | None = None
    ) -> Tensor:
        """Distance [m] from vehicle 0 to the nearest other, shape (...,)."""
        dx = state.x[..., 1:] - state.x[..., :1]
        dy = state.y[..., 1:] - state.y[..., :1]
        return torch.hypot(dx, dy).amin(dim=-1).clamp(max=self.cap)

    def init(self, value: Tensor) -> Tensor:
        return value

    def update(self, carry: Tensor, value: Tensor, alive: Tensor) -> Tensor:
        return torch.where(alive, torch.minimum(carry, value), carry)

    def finalize(self, carry: Tensor) -> Tensor:
        return carry
