import math

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env, data_equivalence  # noqa: E402
from gymnasium.vector import AutoresetMode, SyncVectorEnv  # noqa: E402

from avrisk.assembly import base_distribution  # noqa: E402
from avrisk.gym import ENV_ID, HighwayEnv, HighwayVectorEnv  # noqa: E402
from avrisk.scenario import load_spec  # noqa: E402


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


def short(scenario="highway_idm", horizon=2.0):
    """A bundled scenario's spec cut to ``horizon`` seconds (episodes end often)."""
    spec = load_spec(scenario)
    sim = spec.simulation.model_copy(update={"horizon": horizon})
    return spec.model_copy(update={"simulation": sim})


def test_the_vector_env_is_gymnasiums_sync_vector_env_of_single_envs_bit_for_bit():
    """Gymnasium's own vector env of HighwayEnvs is the reference semantics."""
    spec, n = short(), 6
    envs = gymnasium.make_vec(ENV_ID, num_envs=n, scenario=spec)
    assert isinstance(envs.unwrapped, HighwayVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    reference = SyncVectorEnv([lambda: HighwayEnv(spec) for _ in range(n)])
    for seed in (10, [3, 40, 5, 6, 70, 8]):
        assert data_equivalence(
            envs.reset(seed=seed), reference.reset(seed=seed), exact=True
        )
        envs.action_space.seed(0)
        ended = crashed = 0
        for _ in range(45):  # over two horizons of 20 steps
            actions = envs.action_space.sample()
            got = envs.step(actions)
            assert data_equivalence(got, reference.step(actions), exact=True)
            obs, reward, terminated, truncated, info = got
            assert envs.observation_space.contains(obs)
            ended += int((terminated | truncated).sum())
            crashed += int(info["crash"][terminated].sum())
        assert ended >= 2 * n and crashed >= 1  # autoresets after both ends
    envs.close()


def test_autoreset_restarts_only_the_finished_rows():
    envs = HighwayVectorEnv(8, short(horizon=3.0))
    _, info = envs.reset(seed=0)
    throttle = np.tile(np.array([6.0, 0.0], dtype=np.float32), (8, 1))
    ended = np.zeros(8, dtype=bool)
    while not ended.any():  # full throttle: someone crashes before the horizon
        _, _, terminated, truncated, before = envs.step(throttle)
        ended = terminated | truncated
    assert 0 < ended.sum() < 8 and terminated[ended].all()
    obs, reward, terminated, truncated, after = envs.step(throttle)
    assert np.all(after["t"][ended] == 0) and np.all(reward[ended] == 0.0)
    assert not np.any(terminated[ended] | truncated[ended])
    assert np.all(after["t"][~ended] == before["t"][~ended] + 1)
    assert np.all(after["seed"][ended] != before["seed"][ended])
    assert np.array_equal(after["x"][~ended], info["x"][~ended])
    assert np.array_equal(after["seed"][~ended], info["seed"][~ended])


def test_rollout_i_of_the_vector_env_is_the_single_env_with_its_seed():
    spec, seeds = short(horizon=3.0), [11, 12, 13]
    envs = HighwayVectorEnv(3, spec)
    obs, _ = envs.reset(seed=seeds)
    throttle = np.array([6.0, 0.0], dtype=np.float32)
    vector_obs, ends = [obs], [None] * 3
    for t in range(1, 31):
        obs, _, terminated, truncated, info = envs.step(np.tile(throttle, (3, 1)))
        vector_obs.append(obs)
        for i in np.flatnonzero(terminated | truncated):
            ends[i] = ends[i] or (t, bool(info["crash"][i]))
    assert any(crash for _, crash in ends)  # a crash step is compared too
    for i, seed in enumerate(seeds):
        env = HighwayEnv(spec)
        obs, _ = env.reset(seed=seed)
        assert np.array_equal(obs, vector_obs[0][i])
        done, t = False, 0
        while not done:
            obs, _, terminated, truncated, info = env.step(throttle)
            t += 1
            assert np.array_equal(obs, vector_obs[t][i])
            done = terminated or truncated
        assert (t, info["crash"]) == ends[i]


class _Fixed:
    """A proposal that always draws the same ``X``."""

    def __init__(self, x):
        self.x = x

    def sample(self, n, rng):
        return np.tile(self.x, (n, 1))


def test_a_proposal_given_at_reset_draws_the_autoreset_episodes_too():
    envs = HighwayVectorEnv(2, short(horizon=0.3))
    x = base_distribution(envs._batch.sim.spec).sample(1, np.random.default_rng(1))
    _, info = envs.reset(seed=0, options={"proposal": _Fixed(x[0])})
    for _ in range(3 * 4):  # three episodes of three steps each, and a reset
        *_, info = envs.step(envs.action_space.sample())
        assert np.array_equal(info["x"], np.tile(x, (2, 1)))


def test_given_x_starts_each_sub_environment():
    envs = HighwayVectorEnv(3, short(horizon=0.3))
    x = base_distribution(envs._batch.sim.spec).sample(3, np.random.default_rng(2))
    obs, info = envs.reset(seed=0, options={"x": x})
    assert np.array_equal(info["x"], x)
    assert obs[:, 0] == pytest.approx(x[:, 0])  # the egos start at their s_0
