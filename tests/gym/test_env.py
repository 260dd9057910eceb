import math

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from avrisk.gym import ENV_ID, HighwayEnv, HighwayVectorEnv  # noqa: E402


@pytest.fixture(scope="module")
def env():
    return gymnasium.make(ENV_ID, scenario="highway_idm")


def test_the_registered_env_passes_the_checker(env):
    check_env(env.unwrapped, skip_render_check=True)


def test_spaces_come_from_the_scenario(env):
    sim = env.unwrapped.scenario
    n_beams = sim.config.n_lidar_beams
    assert env.observation_space.shape == (17 + 2 * n_beams,)
    c = sim.config
    assert env.action_space.low.tolist() == pytest.approx([c.accel_min, -c.max_steer])
    assert env.action_space.high.tolist() == pytest.approx([c.accel_max, c.max_steer])


def test_reset_seeds_draw_x_and_a_given_x_is_used(env):
    obs1, info1 = env.reset(seed=3)
    obs2, info2 = env.reset(seed=3)
    assert np.array_equal(obs1, obs2) and np.array_equal(info1["x"], info2["x"])
    obs3, info3 = env.reset(seed=4)
    assert not np.array_equal(info1["x"], info3["x"])
    _, info4 = env.reset(seed=5, options={"x": info1["x"]})
    assert np.array_equal(info4["x"], info1["x"])
    assert obs1[0] == pytest.approx(info1["x"][0])  # the ego's x is X's s_0


def test_an_episode_ends_in_a_crash_or_at_the_horizon(env):
    env.reset(seed=0)
    n_steps = env.unwrapped.scenario.config.n_steps
    # full throttle, no steering: into the traffic ahead or to the horizon
    for t in range(1, n_steps + 1):
        obs, reward, terminated, truncated, info = env.step(
            np.array([6.0, 0.0], dtype=np.float32)
        )
        assert info["t"] == t and math.isfinite(reward) and info["min_ttc"] >= 0
        if terminated or truncated:
            break
    assert terminated == info["crash"]
    assert truncated == (not info["crash"] and t == n_steps)
    if info["crash"]:
        assert reward == -1.0 and info["min_ttc"] == 0.0
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2, dtype=np.float32))


def test_the_agent_drives_the_ego():
    env = HighwayEnv("highway_idm")
    obs0, _ = env.reset(seed=1)
    fast, *_ = env.step(np.array([6.0, 0.0], dtype=np.float32))
    env.reset(seed=1)
    slow, *_ = env.step(np.array([-9.0, 0.0], dtype=np.float32))
    assert fast[3] > obs0[3] > slow[3]  # the ego's speed


def test_the_vector_env_steps_a_batch_in_one_simulator_call():
    envs = gymnasium.make_vec(ENV_ID, num_envs=8, scenario="highway_idm")
    assert isinstance(envs.unwrapped, HighwayVectorEnv)
    obs, info = envs.reset(seed=0)
    assert obs.shape == (8,) + envs.single_observation_space.shape
    assert obs.dtype == np.float32 and envs.observation_space.contains(obs)
    ended = np.zeros(8, dtype=bool)
    steps = 0
    while not ended.all():
        actions = envs.action_space.sample()
        obs, reward, terminated, truncated, info = envs.step(actions)
        steps += 1
        assert reward.shape == terminated.shape == truncated.shape == (8,)
        assert envs.observation_space.contains(obs)
        assert np.all(reward[ended] == 0.0)
        assert np.all(info["min_ttc"] >= 0) and info["crash"].shape == (8,)
        ended |= terminated | truncated
    assert steps <= envs.unwrapped._batch.n_steps
    assert info["t"].tolist() == [steps] * 8
    envs.close()
