"""Scenarios driven by the learned driver network and the lidar_imitation ego."""

import numpy as np
import pytest
import torch

from avrisk.agents.drivers import XI_DIM, LearnedDriver, LearnedEgoPolicy, load_xi_prior
from avrisk.agents.drivers.lane_change import LaneChangeParams, LaneChangingDriver
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution, param_layout
from avrisk.rare import FixedCovNormal, ScaledBeta
from avrisk.rare.problem import chunk_rng, sample_seeds
from avrisk.scenario import (
    ParamLayout,
    ScenarioSpecError,
    build_base_distribution,
    load_spec,
    spec_from_dict,
)
from avrisk.scenario.components import LaneChangeSpec


def shortened(name, horizon):
    """A bundled scenario cut to ``horizon`` seconds (fast tests)."""
    spec = load_spec(name)
    return spec.model_copy(
        update={"simulation": spec.simulation.model_copy(update={"horizon": horizon})}
    )


def traffic(models, ego="idm_mobil", horizon=1.0):
    """Four vehicles on three lanes; ``models`` names the three drivers' models."""
    lanes = (1, 0, 2)
    return spec_from_dict(
        {
            "name": "mix",
            "road": {"n_lanes": 3},
            "drivers": {
                "idm": {"desired_speed": 20.0},
                "learned": {"model": "learned"},
            },
            "ego": {"policy": ego},
            "vehicles": [
                {"lane": 1, "offset": 0.0},
                *(
                    {"lane": lane, "offset": 50.0 * (lane == 1), "driver": m}
                    for lane, m in zip(lanes, models, strict=True)
                ),
            ],
            "simulation": {"horizon": horizon},
            "safety": {"measure": "min_box_ttc"},
        }
    )


def sample(spec, n, seed=0):
    x = base_distribution(spec).sample(n, chunk_rng(seed, 0, 0))
    return x, sample_seeds(seed, 0, np.arange(n))


def frames(spec, x, seeds):
    """Recorded positions and speeds, (B, T+1, A) each, and the result."""
    result = ScenarioSimulator(spec).rollout(x, seeds, record_trace=True)
    trace = result.trace
    return torch.stack([trace.x, trace.y, trace.speed]), result


def test_the_learned_scenario_appends_one_xi_block_to_x():
    layout = param_layout(load_spec("highway_default"))
    assert layout.xi_dim == XI_DIM == 404
    assert layout.dim == 24 + 404 and len(layout.columns) == layout.dim
    assert layout.columns[23:26] == ("veh5.speed", "xi.0", "xi.1")
    assert layout.columns[-1] == "xi.403" and layout.unit("xi.403") == "-"
    assert layout.xi_slice == slice(24, 428)
    default = param_layout(load_spec("highway_idm"))
    assert (default.dim, default.xi_dim) == (24, 0)


def test_the_scenario_layer_asks_for_the_xi_block_it_does_not_know():
    spec = load_spec("highway_default")
    with pytest.raises(ValueError, match="pass xi_dim"):
        ParamLayout.from_spec(spec)
    with pytest.raises(ValueError, match="pass xi_prior"):
        build_base_distribution(spec)
    assert ParamLayout.from_spec(spec, XI_DIM) == param_layout(spec)


def test_p0_of_the_learned_scenario_ends_with_the_shipped_xi_prior():
    spec = load_spec("highway_default")
    p0 = base_distribution(spec)
    assert p0.dim == 428 and len(p0.blocks) == 25
    assert all(isinstance(b, ScaledBeta) for b in p0.blocks[:24])
    xi = p0.blocks[-1]
    assert isinstance(xi, FixedCovNormal) and xi.dim == XI_DIM
    np.testing.assert_array_equal(xi.mean, load_xi_prior().mean)
    x = p0.sample(6, np.random.default_rng(0))
    assert x.shape == (6, 428)
    log_p0 = p0.log_prob(x)
    assert log_p0.shape == (6,) and np.isfinite(log_p0).all()
    np.testing.assert_allclose(
        log_p0 - xi.log_prob(x[:, 24:]),
        base_distribution(load_spec("highway_idm")).log_prob(x[:, :24]),
    )


def test_a_learned_rollout_depends_only_on_its_own_row_and_seed():
    spec = shortened("highway_default", 1.5)
    x, seeds = sample(spec, 5)
    together, result = frames(spec, x, seeds)
    alone, _ = frames(spec, x[3:4], seeds[3:4])
    assert torch.equal(together[:, 3], alone[:, 0])
    again, _ = frames(spec, x[[3, 0]], seeds[[3, 0]])
    assert torch.equal(together[:, [3, 0]], again)
    assert result.f.shape == (5,) and result.steps.tolist() == [15] * 5


def with_actions(spec, actions):
    """``spec`` with its learned drivers acting on ``actions``."""
    drivers = spec.learned_drivers.model_copy(update={"actions": actions})
    return spec.model_copy(update={"learned_drivers": drivers})


def test_the_seed_and_xi_each_change_a_rollout_with_sampled_actions():
    spec = with_actions(shortened("highway_default", 1.0), "sampled")
    x, seeds = sample(spec, 2)
    base, _ = frames(spec, x[:1], seeds[:1])
    other_seed, _ = frames(spec, x[:1], seeds[1:2])
    other_xi = x[:1].copy()
    other_xi[0, 24:] = x[1, 24:]
    other_x, _ = frames(spec, other_xi, seeds[:1])
    env = slice(1, None)  # vehicles 1..5: the learned drivers
    assert not torch.equal(base[:, :, :, env], other_seed[:, :, :, env])
    assert not torch.equal(base[:, :, :, env], other_x[:, :, :, env])


def test_with_mean_actions_a_rollout_is_a_function_of_x_alone():
    spec = shortened("highway_default", 1.0)
    assert spec.learned_drivers.actions == "mean"
    x, seeds = sample(spec, 2)
    base, _ = frames(spec, x[:1], seeds[:1])
    other_seed, _ = frames(spec, x[:1], seeds[1:2])
    other_xi = x[:1].copy()
    other_xi[0, 24:] = x[1, 24:]
    other_x, _ = frames(spec, other_xi, seeds[:1])
    assert torch.equal(base, other_seed)
    env = slice(1, None)
    assert not torch.equal(base[:, :, :, env], other_x[:, :, :, env])


def test_the_xi_search_box_of_p0_follows_the_spec():
    spec = load_spec("highway_default")
    xi = base_distribution(spec).blocks[-1]
    assert np.all(xi.max_shift == 0.0)  # xi_search: 0 -> CE leaves xi at P0
    moved = xi.project(xi.mean + 1.0)
    np.testing.assert_array_equal(moved.mean, xi.mean)
    search = {"xi_search": 0.5, "xi_search_unit": "prior_sd"}
    wide = spec.model_copy(
        update={"learned_drivers": spec.learned_drivers.model_copy(update=search)}
    )
    xi = base_distribution(wide).blocks[-1]
    np.testing.assert_allclose(xi.max_shift, 0.5 * xi.std)
    paper = spec.model_copy(
        update={
            "learned_drivers": spec.learned_drivers.model_copy(
                update={"xi_search": 0.01, "xi_search_unit": "absolute"}
            )
        }
    )
    assert np.all(base_distribution(paper).blocks[-1].max_shift == 0.01)


def test_mixed_traffic_gives_each_vehicle_the_action_of_its_own_model():
    # After one step every vehicle has moved by its own first action, taken on
    # the same initial observation: the mix must match the pure scenarios.
    mixed = traffic(["idm", "learned", "idm"], horizon=0.1)
    x, seeds = sample(mixed, 3)
    got, _ = frames(mixed, x, seeds)
    all_idm, _ = frames(traffic(["idm"] * 3, horizon=0.1), x[:, :16], seeds)
    all_learned, _ = frames(traffic(["learned"] * 3, horizon=0.1), x, seeds)
    assert torch.equal(got[..., [0, 1, 3]], all_idm[..., [0, 1, 3]])
    assert torch.equal(got[..., 2], all_learned[..., 2])
    assert not torch.equal(all_idm[..., 2], all_learned[..., 2])


def test_mixed_traffic_with_the_lidar_ego_is_batch_independent():
    spec = traffic(["learned", "idm", "learned"], ego="lidar_imitation")
    x, seeds = sample(spec, 4, seed=1)
    together, result = frames(spec, x, seeds)
    alone, _ = frames(spec, x[2:3], seeds[2:3])
    assert torch.equal(together[:, 2], alone[:, 0])
    assert result.steps.min().item() >= 1


@pytest.mark.parametrize("models", [["idm"] * 3, ["learned"] * 3])
def test_the_lidar_ego_drives_on_its_mean_action_whatever_the_seed(models):
    spec = traffic(models, ego="lidar_imitation", horizon=0.1)
    x, seeds = sample(spec, 1)
    first, _ = frames(spec, np.repeat(x, 2, axis=0), np.array([seeds[0], 12345]))
    assert torch.equal(first[:, 0, :, 0], first[:, 1, :, 0])
    sim = ScenarioSimulator(spec)
    assert isinstance(sim.ego_policy, LearnedEgoPolicy)


def test_the_traffic_drives_with_the_weights_brake_and_the_lidar_ego_without():
    sim = ScenarioSimulator(load_spec("highway_default"))
    assert sim.net.guard is not None  # the shipped drivers carry one
    assert sim._learned_driver.guard == sim.net.guard
    assert not hasattr(sim.ego_policy, "guard")
    lanes = with_lane_changes(load_spec("highway_default"))
    assert ScenarioSimulator(lanes)._learned_driver.inner.guard == sim.net.guard


def with_lane_changes(spec, **settings):
    """``spec`` with its learned drivers changing lanes (``settings`` as in YAML)."""
    drivers = spec.learned_drivers.model_copy(
        update={"lane_changes": LaneChangeSpec(**settings)}
    )
    return spec.model_copy(update={"learned_drivers": drivers})


def test_lane_changes_are_off_unless_the_spec_turns_them_on():
    default = load_spec("highway_default")
    assert default.learned_drivers.lane_changes is None
    assert "lane_changes" not in default.model_dump(mode="json")["learned_drivers"]
    assert isinstance(ScenarioSimulator(default)._learned_driver, LearnedDriver)
    bundled = load_spec("highway_lane_changes")
    assert bundled.model_dump(mode="json")["learned_drivers"]["lane_changes"] == {}
    actor = ScenarioSimulator(bundled)._learned_driver
    assert isinstance(actor, LaneChangingDriver)
    assert actor.params == LaneChangeParams()
    tuned = with_lane_changes(default, rate_per_hour=36.0, min_gap=7.0)
    params = ScenarioSimulator(tuned)._learned_driver.params
    assert (params.rate, params.min_gap) == (0.01, 7.0)
    assert params.min_ttc == LaneChangeParams().min_ttc


@pytest.mark.parametrize(
    ("setting", "message"),
    [({"min_gap": -1.0}, "min_gap"), ({"rate_per_hour": 1e5}, "rate_per_hour")],
)
def test_lane_change_settings_out_of_range_are_rejected(setting, message):
    data = load_spec("highway_lane_changes").model_dump(mode="json")
    data["learned_drivers"]["lane_changes"] = setting
    with pytest.raises(ScenarioSpecError, match=message):
        spec_from_dict(data)


def test_a_lane_changing_scenario_depends_only_on_its_row_and_seed():
    spec = with_lane_changes(shortened("highway_default", 3.0), rate_per_hour=3600.0)
    x, seeds = sample(spec, 4)
    together, _ = frames(spec, x, seeds)
    alone, _ = frames(spec, x[2:3], seeds[2:3])
    assert torch.equal(together[:, 2], alone[:, 0])
    plain, _ = frames(shortened("highway_default", 3.0), x, seeds)
    assert not torch.equal(together[1], plain[1]), "no lane change: the test is void"
