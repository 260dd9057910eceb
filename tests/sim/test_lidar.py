import math

import pytest
import torch

from avrisk.sim.lidar import beam_directions, lidar_scan, nearest_box, others_index
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

ROAD = Road(n_lanes=3, lane_width=4.0)  # edges at y = 0 and y = 12
N_BEAMS = 20  # beam k at 18 k degrees: 0 ahead, 5 left, 10 behind, 15 right
AHEAD, LEFT, BEHIND, RIGHT = 0, 5, 10, 15


def scan(rows, shape=(1,), max_range=50.0):
    state = VehicleState.from_rows(rows)
    if shape != (1,):
        state = state.map(lambda t: t[0].expand(*shape, -1).contiguous())
    cos, sin = state.cos_sin
    bc, bs = beam_directions(N_BEAMS)
    return lidar_scan(state, cos, sin, ROAD, bc, bs, max_range)


EGO = [0.0, 6.0, 0.0, 20.0, 4.8, 2.0]


@pytest.mark.parametrize("shape", [(), (1,), (7,)])
def test_a_beam_reads_the_distance_to_the_vehicle_ahead_and_its_closing_speed(shape):
    s = scan([EGO, [20.0, 6.0, 0.0, 15.0, 4.0, 2.0]], shape)
    assert s.range.shape == shape + (2, N_BEAMS)
    assert torch.all(s.range[..., 0, AHEAD] == 18.0)
    assert torch.all(s.range_rate[..., 0, AHEAD] == -5.0)
    assert torch.all(s.hit[..., 0, AHEAD] == 1)


def test_the_vehicle_ahead_sees_the_ego_behind_it_approaching():
    s = scan([EGO, [20.0, 6.0, 0.0, 15.0, 4.0, 2.0]])
    assert s.range[0, 1, BEHIND].item() == pytest.approx(20.0 - 2.4, rel=1e-6)
    assert s.range_rate[0, 1, BEHIND].item() == pytest.approx(-5.0, rel=1e-6)
    assert s.hit[0, 1, BEHIND].item() == 0


def test_beams_across_the_road_read_the_road_edges_with_no_vehicle_and_no_rate():
    s = scan([EGO])
    assert s.range[0, 0, LEFT].item() == pytest.approx(6.0, rel=1e-6)
    assert s.range[0, 0, RIGHT].item() == pytest.approx(6.0, rel=1e-6)
    assert s.hit[0, 0, LEFT].item() == -1 and s.hit[0, 0, RIGHT].item() == -1
    assert s.range_rate[0, 0, LEFT].item() == 0.0


def test_a_slanted_beam_reads_the_edge_along_its_slant():
    s = scan([EGO])
    k = 3  # 54 degrees to the left
    assert s.range[0, 0, k].item() == pytest.approx(
        6.0 / math.sin(math.radians(54)), rel=1e-6
    )


def test_a_vehicle_beyond_the_road_edge_is_hidden_by_the_edge():
    offroad = [0.0, -3.0, 0.0, 20.0, 4.0, 2.0]  # its near side is 8 m from the ego
    s = scan([EGO, offroad])
    assert s.range[0, 0, RIGHT].item() == pytest.approx(6.0, rel=1e-6)
    assert s.hit[0, 0, RIGHT].item() == -1
    assert s.range_rate[0, 0, RIGHT].item() == 0.0


def test_a_vehicle_between_the_sensor_and_the_edge_is_seen():
    beside = [0.0, 2.0, 0.0, 20.0, 4.0, 2.0]  # near side at y = 3
    s = scan([EGO, beside])
    assert s.range[0, 0, RIGHT].item() == pytest.approx(3.0, rel=1e-6)
    assert s.hit[0, 0, RIGHT].item() == 1


def test_a_beam_that_hits_nothing_reads_the_maximum_range():
    s = scan([EGO, [20.0, 6.0, 0.0, 15.0, 4.0, 2.0]], max_range=50.0)
    assert s.range[0, 0, BEHIND].item() == 50.0
    assert s.hit[0, 0, BEHIND].item() == -1
    assert s.range_rate[0, 0, BEHIND].item() == 0.0


def test_a_vehicle_beyond_the_range_is_not_seen():
    s = scan([EGO, [60.0, 6.0, 0.0, 15.0, 4.0, 2.0]], max_range=50.0)
    assert s.range[0, 0, AHEAD].item() == 50.0
    assert s.hit[0, 0, AHEAD].item() == -1


def test_beams_turn_with_the_vehicle():
    turned = [0.0, 6.0, math.pi / 2, 20.0, 4.8, 2.0]  # facing the left edge
    s = scan([turned])
    assert s.range[0, 0, AHEAD].item() == pytest.approx(6.0, rel=1e-6)
    assert s.range[0, 0, LEFT].item() == 50.0  # along the road, backwards


def test_the_nearer_of_two_vehicles_on_a_beam_is_the_one_hit():
    s = scan([EGO, [40.0, 6.0, 0.0, 0.0, 4.0, 2.0], [20.0, 6.0, 0.0, 30.0, 4.0, 2.0]])
    assert s.hit[0, 0, AHEAD].item() == 2
    assert s.range[0, 0, AHEAD].item() == 18.0
    assert s.range_rate[0, 0, AHEAD].item() == pytest.approx(10.0)


def test_others_index_lists_everyone_but_oneself():
    assert others_index(3).tolist() == [[1, 2], [0, 2], [0, 1]]


@pytest.mark.parametrize("n_boxes", [1, 2, 5, 7])
def test_boxes_one_at_a_time_give_the_nearest_box_of_all_at_once_bit_for_bit(n_boxes):
    # Compiled code scans one box at a time, eager code all at once: both must
    # give the same distances and the same (lowest) index, on exact ties
    # (boxes in the same place, rays along box edges), misses and hits.
    g = torch.Generator().manual_seed(n_boxes)
    batch, n_rays = 400, 36

    def draw(*shape, scale=1.0):
        return torch.rand(*shape, generator=g) * scale

    sensor = [draw(batch, 1, scale=40.0), torch.round(draw(batch, 1, scale=3.0)) * 4]
    heading = (draw(batch, 1) - 0.5) * 0.4
    heading[::3] = 0.0
    targets = [
        draw(batch, n_boxes, scale=40.0),
        torch.round(draw(batch, n_boxes, scale=3.0)) * 4,
    ]
    targets[0][::5, -1] = targets[0][::5, 0]  # a box behind another, exactly
    target_heading = (draw(batch, n_boxes) - 0.5) * 0.4
    target_heading[::2] = 0.0
    args = (
        *sensor,
        torch.cos(heading),
        torch.sin(heading),
        *targets,
        torch.cos(target_heading),
        torch.sin(target_heading),
        torch.full((batch, n_boxes), 2.4),
        torch.full((batch, n_boxes), 1.0),
        *beam_directions(n_rays),
        30.0,
    )
    d_all, i_all = nearest_box(*args, one_at_a_time=False)
    d_one, i_one = nearest_box(*args, one_at_a_time=True)
    assert d_all.shape == i_all.shape == (batch, n_rays)
    assert torch.isinf(d_all).any() and torch.isfinite(d_all).any()
    assert torch.equal(d_one, d_all)
    assert torch.equal(i_one, i_all)


def test_the_simulators_eager_lidar_gives_the_same_scan_however_the_batch_is_cut(
    monkeypatch,
):
    # Eager, the simulator scans all other vehicles at once while a batch's
    # temporaries fit one slice, and one vehicle at a time in slices beyond.
    from avrisk.safety import MinBoxTTC
    from avrisk.sim import SimConfig, Simulator
    from avrisk.sim import sensing as sensing_module

    g = torch.Generator().manual_seed(3)
    batch, n = 9, 5
    rows = torch.rand(batch, n, 6, generator=g)
    state = VehicleState(
        x=rows[..., 0] * 60.0,
        y=rows[..., 1] * ROAD.width,
        heading=(rows[..., 2] - 0.5) * 0.2,
        speed=rows[..., 3] * 30.0,
        length=torch.full((batch, n), 4.8),
        width=torch.full((batch, n), 2.0),
    )
    cos, sin = state.cos_sin
    sim = Simulator(ROAD, SimConfig(n_lidar_beams=N_BEAMS), measure=MinBoxTTC())
    whole = sim.sensors.scan(state, cos, sin)
    all_at_once = n * (n - 1) * N_BEAMS
    calls = []
    real = sensing_module.lidar_scan

    def spy(state, *args):
        calls.append((state.n_vehicles, len(state.x), args[-1]))
        return real(state, *args)

    monkeypatch.setattr(sensing_module, "lidar_scan", spy)
    # a budget of 4 rollouts one vehicle at a time: slices of 4, 4 and 1
    monkeypatch.setattr(sensing_module, "_EAGER_CHUNK_TESTS", 4 * n * N_BEAMS)
    cut = sim.sensors.scan(state, cos, sin)
    # room for the whole batch all at once: one call, all at once (eager)
    monkeypatch.setattr(sensing_module, "_EAGER_CHUNK_TESTS", batch * all_at_once)
    at_once = sim.sensors.scan(state, cos, sin)
    assert calls == [(n, 4, True), (n, 4, True), (n, 1, True), (n, batch, None)]
    for field in ("range", "range_rate", "hit"):
        assert torch.equal(getattr(cut, field), getattr(whole, field))
        assert torch.equal(getattr(at_once, field), getattr(whole, field))
