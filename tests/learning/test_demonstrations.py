import numpy as np
import pytest
import torch

from avrisk.agents.drivers.features import FEATURE_INDEX, N_FEATURES
from avrisk.learning.imitation.demonstrations import (
    SOURCE_I80,
    SOURCE_IDM,
    Demonstrations,
)
from avrisk.learning.imitation.ngsim_demonstrations import (
    car_following_features,
    i80_pair_demonstrations,
)
from avrisk.learning.imitation.simulated_demonstrations import simulated_demonstrations
from avrisk.learning.ngsim.lateral import (
    LaneCentres,
    lateral_tracks,
    steer_from_heading,
)
from avrisk.learning.ngsim.samples import CarFollowingPairs
from avrisk.sim import Road, VehicleState
from avrisk.sim.dynamics import BicycleLimits, bicycle_step


def one(x):
    return np.array([x], dtype=np.float64)


def test_a_data_sample_becomes_the_features_of_a_two_vehicle_scene():
    road = Road(n_lanes=3, lane_width=4.0)
    f = car_following_features(
        speed=one(12.0),
        leader_speed=one(10.0),
        gap=one(20.0),
        length=one(4.0),
        width=one(2.0),
        leader_length=one(5.0),
        leader_width=one(2.0),
        lane=np.array([1]),
        lateral_offset=one(0.3),
        heading_offset=one(0.01),
        road=road,
    )[0]
    assert f.shape == (N_FEATURES,)
    assert f[FEATURE_INDEX["speed"]] == 12.0
    assert f[FEATURE_INDEX["lateral_offset"]] == pytest.approx(0.3, abs=1e-6)
    assert f[FEATURE_INDEX["heading_offset"]] == pytest.approx(0.01, abs=1e-7)
    assert f[FEATURE_INDEX["left_marking"]] == pytest.approx(1.7, abs=1e-6)
    # Beam 0 from the follower's centre (2 m behind its front) to the leader's rear.
    assert f[FEATURE_INDEX["range_0"]] == pytest.approx(22.0, rel=1e-3)
    assert f[FEATURE_INDEX["range_rate_0"]] == pytest.approx(-2.0, abs=1e-3)


def test_steering_from_heading_inverts_the_simulators_bicycle():
    state = VehicleState.from_rows(
        [[0.0, 0.0, 0.1, 12.0, 4.5, 1.8]], dtype=torch.float64
    )
    steer = 0.04
    moved = bicycle_step(
        state,
        torch.zeros(1, 1, dtype=torch.float64),
        torch.full((1, 1), steer, dtype=torch.float64),
        0.1,
        BicycleLimits(),
    )
    heading = np.array([0.1, moved.heading.item()])
    got = steer_from_heading(heading, np.array([12.0, 12.0]), 4.5, 0.1)
    assert got[0] == pytest.approx(steer, rel=1e-9)
    assert got[1] == got[0]


def pairs_stub(lanes, speeds):
    n = len(speeds)
    z = np.zeros(n)
    return CarFollowingPairs(
        pair_id=np.array([1] * n),
        period=np.array(["0400pm-0415pm"] * n),
        follower_id=np.array([3] * n),
        leader_id=np.array([4] * n),
        lane=np.array(lanes),
        split=np.array(["train"] * n),
        in_manifest=np.array([True] * n),
        t=np.arange(n) * 0.1,
        x_follower=z,
        v_follower=np.array(speeds, dtype=float),
        a_follower=z,
        x_leader=z + 30,
        v_leader=np.full(n, 10.0),
        a_leader=z,
        leader_length=np.full(n, 4.5),
        gap=np.full(n, 25.0),
        dv=z,
    )


def test_car_following_targets_are_forward_differences_without_steering():
    demos = i80_pair_demonstrations(pairs_stub([4, 4, 4], [10.0, 10.2, 10.1]), Road())
    assert len(demos) == 2  # the last sample has no successor
    assert demos.accel.tolist() == pytest.approx([2.0, -1.0], abs=1e-5)
    assert demos.steer_weight.tolist() == [0.0, 0.0]
    assert demos.accel_weight.tolist() == [1.0, 1.0]
    assert set(demos.source.tolist()) == {SOURCE_I80}
    # NGSIM lane 4 of 6 (from the left) is avrisk lane 2 (from the right).
    right = demos.features[0, FEATURE_INDEX["range_15"]]
    assert right == pytest.approx(2.5 * Road().lane_width, rel=1e-5)


def test_drifting_right_in_ngsim_is_a_negative_offset_and_heading_in_avrisk(
    lateral_stub,
):
    n = 200  # long enough that smoothing near the ends does not reach the middle
    lat = lateral_stub(
        [5] * n,
        lateral=5.0 + 0.02 * np.arange(n),  # 0.2 m/s to the right
        speed=np.full(n, 10.0),
        lane=np.full(n, 2),
        length=np.full(n, 4.5),
        x=10.0 * 0.1 * np.arange(n),
    )
    centres = LaneCentres(
        x=np.array([0.0, 500.0]), lanes=(2,), centre=np.full((1, 2), 5.0)
    )
    offset, heading, _ = lateral_tracks(lat, centres)
    assert offset[n // 2] < 0
    assert heading[n // 2] == pytest.approx(np.arctan2(-0.2, 10.0), rel=1e-3)


def test_demonstrations_concatenate_select_and_round_trip(tmp_path):
    d = i80_pair_demonstrations(pairs_stub([2, 2, 2, 2], [5.0, 5.1, 5.3, 5.2]), Road())
    both = Demonstrations.concat([d, d])
    assert len(both) == 6 and len(both.take(both.accel > 0)) == 4
    both.save(tmp_path / "d.npz")
    back = Demonstrations.load(tmp_path / "d.npz")
    assert np.array_equal(back.features, both.features)
    assert back.summary()["ngsim_i80_pairs"]["rows"] == 6


def test_the_idm_mobil_drivers_demonstrate_steering_and_down_weighted_accelerations():
    d = simulated_demonstrations(
        2, seed=0, n_vehicles=3, horizon=1.0, every=2, accel_weight=0.3
    )
    assert len(d) > 0 and np.isfinite(d.features).all()
    assert set(d.source.tolist()) == {SOURCE_IDM}
    assert np.all(d.accel_weight == np.float32(0.3)) and np.all(d.steer_weight == 1.0)
    assert np.unique(d.episode).size <= 6


def test_lane_centres_follow_a_lane_that_drifts_along_the_road(lateral_stub):
    x = np.linspace(0.0, 400.0, 401)
    lat = lateral_stub(
        [1] * 401, x=x, lateral=5.0 + 0.002 * x, lane=np.full(401, 3)
    )  # the lane drifts 0.8 m to the right over 400 m
    centres = LaneCentres.fit(lat, bin_width=50.0)
    got = centres(np.array([3, 3]), np.array([100.0, 300.0]))
    assert got == pytest.approx([5.2, 5.6], abs=0.06)
