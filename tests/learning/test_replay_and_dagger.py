import numpy as np
import torch

from avrisk.agents.idm import IDMDriver, IDMParams
from avrisk.learning.imitation.dagger import ExpertLabeller
from avrisk.learning.imitation.demonstrations import SOURCE_IDM
from avrisk.learning.imitation.simulated_demonstrations import NO_LANE_CHANGE
from avrisk.learning.replay import (
    replay,
    replay_distances,
)
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState
from avrisk.sim.interfaces import Action
from tests.learning.recorded_windows import recorded_windows


def windows(n=3, steps=30):
    t = np.arange(steps + 1) * 0.1
    v_l = np.stack([10 + np.sin(t + k) for k in range(n)])
    return recorded_windows(
        np.full((n, steps + 1), 10.0),
        v_l,
        np.full((n, steps + 1), 20.0),
        has_lateral=np.array([False, True, True][:n]),
    )


def test_a_replayed_leader_follows_its_recorded_speed_profile():
    road = Road()
    win = windows()
    params = IDMParams.full((3, 2), lane_change_threshold=NO_LANE_CHANGE)
    res = replay(win, IDMDriver(params, road), road)
    assert res.v.shape == res.gap.shape == (3, 31)
    assert np.allclose(res.v_l, win.v_l, atol=1e-4)
    assert not res.crash.any() and res.alive.all()
    assert np.allclose(res.gap[:, 0], 20.0, atol=1e-4)
    d = replay_distances(win, res)
    assert set(d) == {"speed", "accel", "jerk", "gap", "crash_rate", "offset"}
    assert all(0.0 <= v <= 1.0 for v in d.values())


class Constant:
    """A learner that always brakes gently and steers a little."""

    noise = None

    def init(self, obs, params):
        return None

    def act(self, obs, state, noise):
        full = torch.full_like(obs.state.x, -0.5)
        return Action(accel=full, steer=torch.full_like(full, 0.01)), None


def test_students_follow_the_learner_and_only_they_are_labelled_by_the_expert():
    road = Road(n_lanes=3)
    one = [[0.0, 1.85, 0.0, 15.0, 4.8, 1.9], [30.0, 5.55, 0.0, 15.0, 4.8, 1.9]]
    state = VehicleState.from_rows([one, one])
    student = torch.tensor([[True, False], [True, False]])
    expert = IDMDriver(IDMParams.full((2, 2)), road)
    rec = ExpertLabeller(Constant(), expert, student, every=1)
    sim = Simulator(road, SimConfig(horizon=0.5), measure=MinTTC(n_rays=4))
    res = sim.run(state, [rec], torch.arange(2), record_trace=True)
    speed = res.trace.speed
    assert torch.allclose(speed[:, -1, 0], torch.full((2,), 15.0 - 0.25), atol=1e-4)
    assert not torch.allclose(speed[:, -1, 1], torch.full((2,), 15.0 - 0.25), atol=1e-3)
    demos = rec.demonstrations(0.3, first_episode=100)
    assert len(demos) == 2 * 5  # two students, five recorded steps
    assert set(demos.episode.tolist()) == {100, 102}
    assert np.all(demos.source == SOURCE_IDM) and np.all(
        demos.accel_weight == np.float32(0.3)
    )
    assert np.all(demos.accel != -0.5)  # labels are the expert's, not the learner's
