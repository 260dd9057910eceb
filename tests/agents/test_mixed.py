"""Per-vehicle mixtures of two driver models."""

import pytest
import torch

from avrisk.agents import Action, MixedDriver
from avrisk.sim import Road, SimConfig, Simulator, VehicleState


class Hold:
    """Every vehicle holds one acceleration [m/s^2] and steers straight."""

    def __init__(self, accel):
        self.accel = accel

    def init(self, obs):
        return None

    def act(self, obs, state):
        x = obs.state.x
        return Action(torch.full_like(x, self.accel), torch.zeros_like(x)), None


def test_a_per_rollout_mask_mixes_each_rollout_its_own_way():
    sim = Simulator(Road(n_lanes=3), SimConfig(horizon=0.5), dtype=torch.float64)
    rows = [[0.0, 1.85, 0.0, 20.0, 4.8, 1.9], [40.0, 5.55, 0.0, 20.0, 4.8, 1.9]]
    state = VehicleState.from_rows([rows, rows], dtype=torch.float64)
    mask = torch.tensor([[False, True], [True, False]])
    result = sim.run(
        state,
        MixedDriver(Hold(1.0), Hold(-2.0), mask),
        torch.tensor([0, 0]),
        record_trace=True,
    )
    expected = torch.tensor([[20.5, 19.0], [19.0, 20.5]], dtype=torch.float64)
    torch.testing.assert_close(result.trace.speed[:, -1], expected)


def test_a_mask_that_is_not_boolean_is_refused():
    with pytest.raises(ValueError, match="bool tensor of shape"):
        MixedDriver(Hold(0.0), Hold(1.0), torch.tensor([0.0, 1.0]))
