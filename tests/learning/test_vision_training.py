"""PilotNet's training on rendered images (tiny runs: the pipeline, not its skill)."""

import functools
import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import avrisk.learning.vision as vision
from avrisk.agents.vision import PilotNet
from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.parts import base_distribution
from avrisk.cli.app import app
from avrisk.learning.vision import VisionTrainConfig, collect_frames, train_vision
from avrisk.scenario import load_spec

TINY = VisionTrainConfig(
    rollouts=2,
    frame_every=5,
    dagger_rounds=1,
    epochs=1,
    batch_size=4,
    val_rollouts=1,
    eval_rollouts=2,
    horizon=0.5,
)


@pytest.fixture(scope="module")
def lidar_sim():
    spec = vision._with_lidar_ego(load_spec("highway_vision"), 0.5)
    return ScenarioSimulator(spec), base_distribution(spec)


def test_frames_are_recorded_every_few_steps_with_the_experts_steering(lidar_sim):
    sim, base = lidar_sim
    x = base.sample(3, np.random.default_rng(0))
    images, labels = collect_frames(sim, x, np.arange(3), None, 2)
    assert images.dtype == torch.uint8 and tuple(images.shape) == (9, 3, 66, 200)
    assert labels.shape == (9,)  # t = 0, 2, 4 for each of 3 rollouts
    steer = []

    class Spy:  # the expert's own steering at t = 0, for rollout 0..2
        def __getattr__(self, name):
            return getattr(expert, name)

        def act(self, obs, state, noise):
            action, state = expert.act(obs, state, noise)
            if obs.step == 0:
                steer.append(action.steer[:, 0])
            return action, state

    expert = sim.ego_policy
    sim.ego_policy = Spy()
    try:
        sim.rollout(x, np.arange(3))
    finally:
        sim.ego_policy = expert
    assert torch.equal(labels[:3], steer[0])
    assert sim.ego_policy is expert


def test_perturbed_steering_moves_the_ego_but_not_the_labels_of_a_state(lidar_sim):
    sim, base = lidar_sim
    x = base.sample(2, np.random.default_rng(0))
    plain = collect_frames(sim, x, np.arange(2), None, 1)
    noisy = collect_frames(sim, x, np.arange(2), None, 1, steer_noise=0.05)
    assert torch.equal(noisy[0][:2], plain[0][:2])  # t = 0: same state, same image
    assert torch.equal(noisy[1][:2], plain[1][:2])
    assert not torch.equal(noisy[0][-2:], plain[0][-2:])  # then the ego moved


def test_a_tiny_training_run_is_reproducible_and_writes_weights_and_report(tmp_path):
    report = train_vision(3, tmp_path / "a", config=TINY)
    again = train_vision(3, tmp_path / "b", config=TINY)
    a = (tmp_path / "a" / "pilotnet.npz").read_bytes()
    assert a == (tmp_path / "b" / "pilotnet.npz").read_bytes()
    assert report["closed_loop"] == again["closed_loop"]
    assert PilotNet.load(tmp_path / "a" / "pilotnet.npz").steer_scale > 0
    written = json.loads((tmp_path / "a" / "training_report.json").read_text())
    assert written["seed"] == 3 and [r["round"] for r in written["rounds"]] == [0, 1]
    assert set(written["closed_loop"]) == {"lidar_imitation", "vision_pilotnet"}
    assert written["rounds"][1]["frames"] == 2 * written["rounds"][0]["frames"]


def test_train_vision_command_writes_the_files_and_names_them(tmp_path, monkeypatch):
    monkeypatch.setattr(
        vision, "train_vision", functools.partial(vision.train_vision, config=TINY)
    )
    out = tmp_path / "vision"
    result = CliRunner().invoke(app, ["train-vision", "--seed", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "pilotnet.npz" in result.output and "training_report.json" in result.output
    assert json.loads((out / "training_report.json").read_text())["seed"] == 1
