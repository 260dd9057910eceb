import pytest
import torch

from avrisk.agents.drivers.features import (
    FEATURE_INDEX,
    FEATURE_NAMES,
    FEATURE_UNITS,
    N_BEAMS,
    N_FEATURES,
    assemble_features,
    features_from_observation,
)
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator, VehicleState


def observe(rows, road, **config):
    sim = Simulator(
        road, SimConfig(**config), measure=MinTTC(n_rays=1), dtype=torch.float64
    )
    state = VehicleState.from_rows(rows, dtype=torch.float64)
    return sim.observe(state, torch.zeros(state.batch_size, dtype=torch.int64))


def test_the_layout_has_eleven_scalars_then_twenty_ranges_then_twenty_rates():
    assert N_FEATURES == 51 == 11 + 2 * N_BEAMS
    assert FEATURE_NAMES[:3] == ("length", "width", "speed")
    assert FEATURE_NAMES[8:11] == ("collided", "offroad", "reversing")
    assert FEATURE_INDEX["range_0"] == 11 and FEATURE_INDEX["range_19"] == 30
    assert FEATURE_INDEX["range_rate_0"] == 31 and FEATURE_NAMES[-1] == "range_rate_19"
    assert set(FEATURE_UNITS) == set(FEATURE_NAMES)
    assert FEATURE_UNITS["heading_offset"] == "rad"


def test_a_follower_behind_a_leader_sees_the_known_distances_and_rates():
    # 3 lanes of 4 m; follower 0.5 m left of lane 1's centre, leader 30 m ahead.
    road = Road(n_lanes=3, lane_width=4.0)
    obs = observe(
        [[0.0, 6.5, 0.0, 20.0, 4.0, 2.0], [30.0, 6.0, 0.0, 15.0, 5.0, 2.0]], road
    )
    f = features_from_observation(obs)[0, 0]
    expect = {
        "length": 4.0,
        "width": 2.0,
        "speed": 20.0,
        "lateral_offset": 0.5,
        "heading_offset": 0.0,
        "left_marking": 1.5,
        "right_marking": 2.5,
        "curvature": 0.0,
        "collided": 0.0,
        "offroad": 0.0,
        "reversing": 0.0,
        "range_0": 27.5,  # to the leader's rear edge at x = 30 - 2.5
        "range_rate_0": -5.0,  # closing at 20 - 15 m/s
        "range_5": 5.5,  # beam 5 points left: road edge at y = 12
        "range_rate_5": 0.0,
        "range_15": 6.5,  # beam 15 points right: road edge at y = 0
        "range_10": 50.0,  # behind: nothing within the lidar range
    }
    for name, value in expect.items():
        assert f[FEATURE_INDEX[name]].item() == pytest.approx(value, abs=1e-9), name


def test_indicators_are_one_for_a_crashed_reversing_vehicle_off_the_road():
    road = Road(n_lanes=2, lane_width=3.5)
    # Vehicle 0 faces backwards and pokes over the right edge; vehicle 1 overlaps it.
    obs = observe(
        [[0.0, 0.5, 3.14159, 5.0, 4.0, 2.0], [1.0, 0.8, 0.0, 5.0, 4.0, 2.0]], road
    )
    f = features_from_observation(obs)[0, 0]
    for name in ("collided", "offroad", "reversing"):
        assert f[FEATURE_INDEX[name]].item() == 1.0, name


def test_driver_features_have_the_papers_layout():

    sim = Simulator(Road(n_lanes=3), SimConfig(n_lidar_beams=20), measure=MinTTC())
    s = VehicleState.from_rows(
        [[0.0, 5.0, 0.0, 10.0, 4.0, 2.0], [20.0, 5.0, 0.0, 10.0, 4.0, 2.0]]
    )
    obs = sim.observe(s, torch.zeros(1, dtype=torch.int64))
    feats = features_from_observation(obs)
    assert feats.shape == (1, 2, 11 + 40)
    assert feats[0, 0, 0].item() == 4.0 and feats[0, 0, 2].item() == 10.0
    assert feats[0, 0, 11].item() == pytest.approx(18.0)  # beam 0 range


def test_assembly_rejects_a_lidar_with_another_number_of_beams():
    z = torch.zeros(3)
    with pytest.raises(ValueError, match="20 lidar beams"):
        assemble_features(
            length=z,
            width=z,
            speed=z,
            lateral_offset=z,
            heading_offset=z,
            left_marking=z,
            right_marking=z,
            curvature=z,
            collided=z,
            offroad=z,
            reversing=z,
            lidar_range=torch.zeros(3, 8),
            lidar_range_rate=torch.zeros(3, 8),
        )
