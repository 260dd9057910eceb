"""Traffic of two driver models: each vehicle follows one of them.

A scenario may drive some vehicles with IDM+MOBIL and others with the learned
driver network. :class:`MixedDriver` runs both models on the whole batch (one
batched pass each, every vehicle) and gives each vehicle the action of its own
model: a model's work on the vehicles it does not drive is wasted, but every
operation stays elementwise along the batch, so a rollout's actions depend
only on its own rows (the contract of :mod:`avrisk.agents.policy`).

Examples
--------
>>> import torch
>>> from avrisk.sim import Road, SimConfig, Simulator, VehicleState
>>> class Hold:  # a driver model: every vehicle brakes at a fixed rate
...     def __init__(self, accel):
...         self.accel = accel
...     def init(self, obs):
...         return None
...     def act(self, obs, state):
...         x = obs.state.x
...         return Action(torch.full_like(x, self.accel), torch.zeros_like(x)), None
>>> sim = Simulator(Road(n_lanes=3), SimConfig(horizon=1.0))
>>> state = VehicleState.from_rows(
...     [[0.0, 1.85, 0.0, 20.0, 4.8, 1.9], [40.0, 5.55, 0.0, 20.0, 4.8, 1.9]]
... )
>>> mix = MixedDriver(Hold(0.0), Hold(-2.0), torch.tensor([False, True]))
>>> res = sim.run(state, mix, torch.tensor([0]), record_trace=True)
>>> [round(v, 3) for v in res.trace.speed[0, -1].tolist()]
[20.0, 18.0]
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor

from avrisk.agents.policy import Action, DriverModel, reads_lidar
from avrisk.sim.observation import Observation

__all__ = ["MixedDriver"]


class MixedDriver:
    """Vehicles drive with ``second`` where ``use_second``, else with ``first``.

    A :class:`~avrisk.agents.policy.DriverModel` whose state is the pair of
    the two models' states.

    Parameters
    ----------
    first, second : DriverModel
        Both act for every vehicle of the batch, fields of shape (B, A).
    use_second : Tensor of bool, shape (A,) or (B, A)
        Per vehicle (or per rollout and vehicle), whether ``second`` drives it.
    """

    def __init__(
        self, first: DriverModel, second: DriverModel, use_second: Tensor
    ) -> None:
        if use_second.dim() not in (1, 2) or use_second.dtype != torch.bool:
            raise ValueError(
                "use_second must be a bool tensor of shape (A,) or (B, A); got "
                f"{use_second.dtype} of shape {tuple(use_second.shape)}"
            )
        self.first = first
        self.second = second
        self.reads_lidar = reads_lidar(first) or reads_lidar(second)
        # (1, A): Action.where broadcasts masks from the leading dimension.
        self.use_second = use_second.reshape(-1, use_second.shape[-1])

    def init(self, obs: Observation) -> tuple[Any, Any]:
        """Both models' initial states."""
        return self.first.init(obs), self.second.init(obs)

    def act(
        self, obs: Observation, state: tuple[Any, Any]
    ) -> tuple[Action, tuple[Any, Any]]:
        """Every vehicle's action from its own model, fields of shape (B, A)."""
        first_state, second_state = state
        mine, first_state = self.first.act(obs, first_state)
        theirs, second_state = self.second.act(obs, second_state)
        return theirs.where(self.use_second, mine), (first_state, second_state)
