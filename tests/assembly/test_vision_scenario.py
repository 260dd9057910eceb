"""``highway_vision`` built: a vision rollout depends only on its X and seed."""

import numpy as np
import torch

from avrisk.agents.vision import PilotNetEgo
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution
from avrisk.render import RayCastCamera
from avrisk.scenario import load_spec
from tests.scenario_files import shortened_scenario


def test_a_vision_rollout_is_the_same_alone_and_in_a_batch_in_any_order(tmp_path):
    spec = load_spec(shortened_scenario(tmp_path, 0.6, scenario="highway_vision"))
    sim = ScenarioSimulator(spec)
    assert isinstance(sim.ego_policy, PilotNetEgo)
    assert isinstance(sim.camera, RayCastCamera)
    x = base_distribution(spec).sample(5, np.random.default_rng(4))
    seeds = np.arange(5) + 10
    batch = sim.rollout(x, seeds, record_trace=True)
    order = [3, 0, 4, 1, 2]
    permuted = sim.rollout(x[order], seeds[order], record_trace=True)
    assert torch.equal(permuted.trace.y, batch.trace.y[order])
    for i in (0, 3):
        alone = sim.rollout(x[i : i + 1], seeds[i : i + 1], record_trace=True)
        assert torch.equal(alone.trace.y[0], batch.trace.y[i])
        assert torch.equal(alone.f[0], batch.f[i])


def test_a_scenario_whose_ego_reads_no_camera_gets_none():
    assert ScenarioSimulator(load_spec("highway_default")).camera is None


def test_what_defines_p_for_the_vision_scenario_hashes_pilotnets_weights():
    from avrisk.agents.vision.store import PILOTNET_FILE, default_vision_dir
    from avrisk.assembly import SimulationObjective
    from avrisk.fingerprint import sha256_file

    weights = SimulationObjective(load_spec("highway_vision")).definition()
    assert weights["weights_sha256"][PILOTNET_FILE] == sha256_file(
        default_vision_dir() / PILOTNET_FILE
    )
    lidar = SimulationObjective(load_spec("highway_default")).definition()
    assert PILOTNET_FILE not in lidar["weights_sha256"]
