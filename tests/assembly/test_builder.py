"""From named scenario parameters to the simulator's inputs, and rollouts."""

import numpy as np
import pytest
import torch

from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import (
    base_distribution,
    driver_params,
    initial_state,
    param_layout,
    road_from_spec,
    sim_config_from_spec,
)
from avrisk.safety import MinBoxTTC, MinTTC
from avrisk.scenario import ScenarioParams, load_spec, spec_from_dict


@pytest.fixture(scope="module")
def spec():
    return spec_from_dict(
        {
            "name": "two",
            "road": {"n_lanes": 3, "lane_width": 4.0},
            "drivers": {"slow": {"desired_speed": 12.0, "politeness": 0.7}},
            "ego": {"params": {"desired_speed": 31.0}},
            "vehicles": [
                {"lane": 1, "offset": 0.0},
                {
                    "lane": 2,
                    "offset": 30.0,
                    "length": 12.0,
                    "width": 2.5,
                    "driver": "slow",
                },
            ],
            "simulation": {"horizon": 1.0},
            "safety": {"n_rays": 24},
        }
    )


def test_initial_state_places_each_vehicle_relative_to_its_slot(spec):
    layout = param_layout(spec)
    x = np.zeros((1, layout.dim))
    x[0, layout.index("veh0.s")] = 90.0
    x[0, layout.index("veh1.s")] = 100.0
    x[0, layout.index("veh1.t")] = -0.2
    x[0, layout.index("veh1.heading")] = 90.0
    x[0, layout.index("veh1.speed")] = 14.0
    state = initial_state(
        ScenarioParams.from_flat(x, layout), spec, dtype=torch.float64
    )
    assert state.x.tolist() == [[90.0, 130.0]]
    assert state.y[0].tolist() == pytest.approx([6.0, 9.8])
    assert state.heading[0, 1].item() == pytest.approx(np.pi / 2)
    assert state.speed[0].tolist() == [0.0, 14.0]
    assert state.length[0].tolist() == [4.8, 12.0] and state.width[0].tolist() == [
        1.9,
        2.5,
    ]


def test_driver_params_put_the_ego_policy_in_slot_0_and_drivers_elsewhere(spec):
    p = driver_params(spec, 3)
    assert p.desired_speed.shape == (3, 2)
    assert p.desired_speed[:, 0].tolist() == [31.0] * 3
    assert p.desired_speed[:, 1].tolist() == [12.0] * 3
    assert p.politeness[0, 1].item() == pytest.approx(0.7)


def test_the_static_pieces_follow_the_spec(spec):
    road = road_from_spec(spec)
    assert (road.n_lanes, road.lane_width, road.length) == (3, 4.0, 500.0)
    cfg = sim_config_from_spec(spec)
    assert (cfg.dt, cfg.horizon, cfg.n_lidar_beams) == (0.1, 1.0, 20)


@pytest.mark.parametrize(
    ("safety", "kind", "n_rays"),
    [
        ({"measure": "min_ttc", "n_rays": 24}, MinTTC, 24),
        ({"measure": "min_box_ttc"}, MinBoxTTC, None),
    ],
)
def test_the_spec_chooses_the_safety_measure(spec, safety, kind, n_rays):
    raw = spec.model_dump(mode="json")
    raw["safety"] = safety
    sim = ScenarioSimulator(spec_from_dict(raw))
    assert type(sim.simulator.measure) is kind
    assert getattr(sim.simulator.measure, "n_rays", None) == n_rays


def test_a_parallel_pass_is_a_near_collision_only_for_the_ray_measure(spec):
    # The "slow" truck one lane left, its centre level with the ego, which
    # passes it 15 m/s faster with both headings straight: the rectangles never
    # meet, but rays slanted across the truck's side see it approach.
    raw = spec.model_dump(mode="json")
    layout = param_layout(spec)
    x = np.zeros((1, layout.dim))
    values = {"veh0.s": 100.0, "veh1.s": 70.0, "veh0.speed": 20.0, "veh1.speed": 5.0}
    for name, value in values.items():
        x[0, layout.index(name)] = value
    f = {}
    for measure in ("min_ttc", "min_box_ttc"):
        raw["safety"] = {"measure": measure, "n_rays": 360}
        f[measure] = ScenarioSimulator(spec_from_dict(raw)).min_ttc(x, np.zeros(1))[0]
    assert f["min_box_ttc"] == np.inf
    assert f["min_ttc"] < 1.0


def test_a_rollout_of_the_bundled_default_is_batch_independent():
    spec = load_spec("highway_idm")
    spec = spec.model_copy(
        update={
            "simulation": spec.simulation.model_copy(update={"horizon": 1.0}),
            "safety": spec.safety.model_copy(update={"n_rays": 36}),
        }
    )
    from avrisk.rare.problem import chunk_rng, sample_seeds

    sim = ScenarioSimulator(spec)
    x = base_distribution(spec).sample(5, chunk_rng(0, 0, 0))
    seeds = sample_seeds(0, 0, np.arange(5))
    together = sim.rollout(x, seeds)
    alone = sim.rollout(x[3:4], seeds[3:4])
    assert together.f.shape == (5,) and together.steps.dtype == torch.int64
    assert (together.status == 0).all() and together.contact.dtype == torch.int8
    assert together.f[3].item() == alone.f[0].item()
    assert sim.min_ttc(x, seeds).dtype == np.float64


def test_seeds_of_the_wrong_shape_are_refused(spec):
    sim = ScenarioSimulator(spec)
    with pytest.raises(ValueError, match="seeds"):
        sim.rollout(np.full((2, 8), 1.0), np.arange(3))


def test_a_scenario_file_may_name_the_constant_ego(spec):
    """``ego: {policy: constant}`` builds with the scenario's context and drives."""
    raw = spec.model_dump(mode="json")
    raw["ego"] = {"policy": "constant", "params": {"accel": 1.5}}
    sim = ScenarioSimulator(spec_from_dict(raw))
    x = base_distribution(sim.spec).sample(3, np.random.default_rng(0))
    result = sim.rollout(x, np.arange(3), record_trace=True)
    assert (result.status == 0).all() and not result.crash.any()
    gained = result.trace.speed[:, -1, 0] - result.trace.speed[:, 0, 0]
    torch.testing.assert_close(gained, torch.full((3,), 1.5), rtol=0, atol=1e-5)
