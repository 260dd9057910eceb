import math

import pytest
import torch

from avrisk.sim import Road, VehicleState
from avrisk.sim.observation import lane_features


def test_lane_centres_and_indices_follow_the_right_edge_frame():
    road = Road(n_lanes=6, lane_width=3.7)
    assert road.width == pytest.approx(22.2)
    assert road.lane_center_y(0) == pytest.approx(1.85)
    assert torch.equal(road.lane_center_y(torch.tensor([5])), torch.tensor([20.35]))
    y = torch.tensor([-1.0, 0.1, 3.69, 3.71, 22.1, 30.0])
    assert road.lane_index(y).tolist() == [0, 0, 0, 1, 5, 5]


def test_a_road_rejects_sizes_that_make_no_sense():
    with pytest.raises(ValueError, match="n_lanes"):
        Road(n_lanes=0)
    with pytest.raises(ValueError, match="lane_width"):
        Road(lane_width=-1.0)


def test_corners_of_a_turned_vehicle_are_rotated_about_its_centre():
    s = VehicleState.from_rows([[10.0, 5.0, math.pi / 2, 0.0, 4.0, 2.0]])
    corners = s.corners[0, 0]
    expected = torch.tensor([[9.0, 7.0], [9.0, 3.0], [11.0, 3.0], [11.0, 7.0]])
    assert torch.allclose(corners, expected, atol=1e-6)


def test_validate_names_the_field_that_is_wrong():
    good = VehicleState.from_rows([[0.0, 1.0, 0.0, 10.0, 4.0, 2.0]])
    assert good.validate() is good
    with pytest.raises(ValueError, match="width"):
        VehicleState.from_rows([[0.0, 1.0, 0.0, 10.0, 4.0, 0.0]]).validate()
    with pytest.raises(ValueError, match="non-finite"):
        good.map(lambda t: t * math.nan).validate()
    with pytest.raises(ValueError, match="same shape"):
        VehicleState(
            good.x, good.y, good.heading, good.speed, good.length, good.width[:, :0]
        ).validate()


def test_states_index_stack_and_move_as_one():
    s = VehicleState.from_rows(
        [[[0.0, 1.0, 0.0, 10.0, 4.0, 2.0]], [[5.0, 1.0, 0.1, 12.0, 4.0, 2.0]]]
    )
    assert s.shape == (2, 1)
    assert s[1:].x.tolist() == [[5.0]]
    assert VehicleState.cat([s, s]).shape == (4, 1)
    assert s.to(dtype=torch.float64).x.dtype == torch.float64
    mixed = s.where(torch.tensor([True, False]), s.map(lambda t: t + 1))
    assert mixed.x.tolist() == [[0.0], [6.0]]


def test_lane_features_measure_offsets_and_distances_from_the_lane():
    road = Road(n_lanes=3, lane_width=4.0)
    s = VehicleState.from_rows([[0.0, 5.0, 0.1, 10.0, 4.0, 2.0]])
    f = lane_features(s, road)
    assert f.lane.item() == 1
    assert f.lateral_offset.item() == pytest.approx(-1.0)
    assert f.heading_offset.item() == pytest.approx(0.1)
    assert f.left_marking.item() == pytest.approx(3.0)
    assert f.right_marking.item() == pytest.approx(1.0)
    assert f.left_edge.item() == pytest.approx(7.0)
    assert f.right_edge.item() == pytest.approx(5.0)
