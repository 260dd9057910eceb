"""A user's own components, named by import path in tests and spec files.

``tests.user_components:HoldSpeedEgo`` is what a user writes in a scenario
(``ego: {policy: "tests.user_components:HoldSpeedEgo", params: {speed: 25}}``).
"""

import torch
from pydantic import BaseModel, Field

from avrisk.agents.policy import Action


class HoldSpeedEgo:
    """An ego that drives straight on and holds ``speed`` (proportional control)."""

    class Params(BaseModel):
        """What ``params`` may set."""

        speed: float = Field(20.0, ge=0.0, description="Target speed [m/s].")
        gain: float = Field(0.5, gt=0.0, description="Accel per speed error [1/s].")

    reads_lidar = False

    def __init__(self, speed: float = 20.0, gain: float = 0.5) -> None:
        self.speed, self.gain = speed, gain

    def init(self, obs):
        """No memory."""
        return None

    def act(self, obs, state):
        """Accelerate towards ``speed``, wheels straight; fields of shape (B,)."""
        v = obs.state.speed[:, 0]
        accel = self.gain * (self.speed - v)
        return Action(accel=accel, steer=torch.zeros_like(v)), None


class MisdeclaredEgo:
    """An ego whose ``Params`` is not a Pydantic model."""

    Params = dict


#: Not a component: what an import path must not name.
SPEED_LIMIT = 30.0
