"""Other traffic drivers in a scenario, the ego held at the shipped weights."""

import dataclasses
import shutil

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    default_drivers_dir,
    load_driver_net,
    load_xi_prior,
)
from avrisk.assembly.objective import SimulationObjective
from avrisk.assembly.traffic import TrafficDrivers
from avrisk.fingerprint import sha256_file
from avrisk.scenario import load_spec

N = 12


@pytest.fixture(scope="module")
def spec():
    return load_spec("highway_default")


@pytest.fixture(scope="module")
def draws(spec):
    x = (
        SimulationObjective(spec)
        .base_distribution()
        .sample(N, np.random.default_rng(0))
    )
    return x, np.arange(N, dtype=np.int64) + 100


@pytest.fixture
def other_drivers(tmp_path):
    """The shipped drivers with their trunk's first layer perturbed."""
    net = load_driver_net()
    with torch.no_grad():
        for p in list(net.parameters())[:1]:
            p.add_(
                0.3 * torch.randn(p.shape, generator=torch.Generator().manual_seed(1))
            )
    net.save(tmp_path / DRIVER_NET_FILE)
    shutil.copy(default_drivers_dir() / XI_PRIOR_FILE, tmp_path / XI_PRIOR_FILE)
    return tmp_path


def test_the_shipped_drivers_named_as_traffic_give_the_same_rollouts(spec, draws):
    x, seeds = draws
    default = SimulationObjective(spec)(x, seeds)["f"]
    named = SimulationObjective(spec, traffic=TrafficDrivers(default_drivers_dir()))
    np.testing.assert_array_equal(named(x, seeds)["f"], default)


def test_other_traffic_leaves_the_ego_on_the_shipped_network(
    spec, draws, other_drivers
):
    x, seeds = draws
    objective = SimulationObjective(spec, traffic=TrafficDrivers(other_drivers))
    sim = objective.simulator
    shipped = load_driver_net().state_dict()
    ego_net = sim.net.state_dict()  # the net the lidar ego was built with
    traffic_net = sim._learned_driver.net.state_dict()
    assert all(torch.equal(ego_net[k], shipped[k]) for k in shipped)
    assert not all(torch.equal(traffic_net[k], shipped[k]) for k in shipped)
    assert not np.array_equal(
        objective(x, seeds)["f"], SimulationObjective(spec)(x, seeds)["f"]
    )
    hashes = objective.definition()["weights_sha256"]
    assert hashes[DRIVER_NET_FILE] == sha256_file(
        default_drivers_dir() / DRIVER_NET_FILE
    )
    assert hashes[f"traffic/{DRIVER_NET_FILE}"] == sha256_file(
        other_drivers / DRIVER_NET_FILE
    )
    assert XI_PRIOR_FILE not in hashes and f"traffic/{XI_PRIOR_FILE}" in hashes


def test_the_traffic_brake_can_be_taken_off_and_p0_takes_the_traffics_prior(
    spec, other_drivers
):
    off = SimulationObjective(spec, traffic=TrafficDrivers(other_drivers, None))
    assert off.simulator._learned_driver.guard is None
    assert off.simulator.net.guard is not None  # the shipped network's file is intact
    assert off.definition()["traffic_guard"] is None
    shipped = SimulationObjective(spec).base_distribution()
    x = shipped.sample(4, np.random.default_rng(2))
    np.testing.assert_array_equal(
        off.base_distribution().log_prob(x), shipped.log_prob(x)
    )
    prior = load_xi_prior(other_drivers / XI_PRIOR_FILE)
    shifted = dataclasses.replace(prior, mean=prior.mean + 0.01)
    shifted.save(other_drivers / XI_PRIOR_FILE)
    moved = SimulationObjective(spec, traffic=TrafficDrivers(other_drivers))
    assert moved.base_distribution().dim == shipped.dim
    assert (moved.base_distribution().log_prob(x) != shipped.log_prob(x)).all()
