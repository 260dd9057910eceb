import math
import shutil

import pytest
import torch

import avrisk.render.raycast as raycast
from avrisk.render import PALETTE, CameraModel, RayCastCamera, RoadPaint
from avrisk.sim import Road, SemanticClass, VehicleState

ROAD = Road(n_lanes=3, lane_width=3.7)  # edges at y = 0 and 11.1
MID = 1.5 * 3.7  # centre of the middle lane
# 40 x 20 pixels, 90 degrees: focal length 20 pixels; level camera 1 m ahead
# of the ego's centre, 1.4 m up.
LEVEL = CameraModel(width=40, height=20, hfov=90.0, pitch=0.0, mount_height=1.4)


def ego(x=0.0, y=MID, heading=0.0):
    return [x, y, heading, 20.0, 4.8, 1.9]


def render(rows, model=LEVEL, heights=None, road=ROAD):
    camera = RayCastCamera(road, model, heights=heights)
    return camera(VehicleState.from_rows(rows))


def test_a_box_ahead_fills_the_pixels_its_rear_face_subtends_at_its_depth():
    # Rear face 10 m ahead of the camera, 4 m wide, from 0 to 2.8 m high:
    # columns with |a| < 2/10 (j = 16..23) and rows with |b| < 1.4/10 (7..12).
    box = [1.0 + 10.0 + 1.0, MID, 0.0, 10.0, 2.0, 4.0]
    frame = render([ego(), box], heights=[1.5, 2.8])
    vehicle = frame.segmentation[0] == SemanticClass.VEHICLE
    expected = torch.zeros(20, 40, dtype=torch.bool)
    expected[7:13, 16:24] = True
    assert torch.equal(vehicle, expected)
    assert torch.all(frame.depth[0][expected] == 10.0)
    rear = torch.tensor(PALETTE[SemanticClass.VEHICLE])
    assert torch.allclose(frame.rgb[0, :, 10, 20], rear)


def test_a_box_behind_the_camera_or_beside_the_view_is_not_drawn():
    behind = [-10.0, MID, 0.0, 20.0, 4.8, 1.9]
    beside = [0.0, MID + 3.7, 0.0, 20.0, 4.8, 1.9]  # outside the 90-degree view
    frame = render([ego(), behind, beside])
    assert not bool((frame.segmentation == SemanticClass.VEHICLE).any())


def test_rows_above_the_horizon_are_sky_and_rows_below_are_ground():
    model = CameraModel(width=20, height=66, pitch=5.0)
    horizon = model.horizon_row  # 33 - f tan(5 deg) = 31.48
    focal = 10 / math.tan(math.radians(30))
    assert horizon == pytest.approx(33 - focal * math.tan(math.radians(5)), 1e-9)
    wide = Road(n_lanes=3, lane_width=100.0)  # ground everywhere below
    frame = render([ego(y=150.0)], model, road=wide)
    seg = frame.segmentation[0]
    rows = torch.arange(66).unsqueeze(-1).expand(66, 20) + 0.5
    assert torch.equal(seg == SemanticClass.SKY, rows < horizon)
    assert torch.all(torch.isinf(frame.depth[0][rows < horizon]))
    assert torch.all(torch.isfinite(frame.depth[0][rows > horizon]))


def test_the_ground_depth_of_a_row_is_the_mount_height_over_the_ray_slope():
    frame = render([ego()])
    # Level camera: row i looks down by b = (i + 0.5 - 10) / 20.
    for i in (12, 15, 19):
        b = (i + 0.5 - 10) / 20
        assert frame.depth[0, i, 5].item() == pytest.approx(1.4 / b, rel=1e-6)


def test_a_lane_line_appears_in_the_column_of_its_bearing_and_dashes_stay_on_the_road():
    # 200 columns at 90 degrees (f = 100), level camera; row 60 sees the ground
    # at t = 1.4 / 0.275 = 5.09 m, where the left lane line (1.85 m left of the
    # camera) is at a = 1.85 / t, column 100 - 100 a - 0.5 = 63.2.
    model = CameraModel(width=200, height=66, hfov=90.0, pitch=0.0)
    t = 1.4 / ((60.5 - 33) / 100)
    on_dash = -1.0 - t + 1.0  # the ground point at x = 1 m: on a dash (x mod 12 < 3)
    row = render([ego(x=on_dash)], model).segmentation[0, 60]
    left = torch.nonzero(row[:100] == SemanticClass.LANE_MARKING).flatten().float()
    assert len(left) >= 2
    assert left.mean().item() == pytest.approx(100 - 100 * 1.85 / t - 0.5, abs=0.5)
    right = torch.nonzero(row[100:] == SemanticClass.LANE_MARKING).flatten().float()
    assert right.mean().item() + 100 == pytest.approx(
        100 + 100 * 1.85 / t - 0.5, abs=0.5
    )
    # 6 m further on the same spot of the road is in a gap between dashes.
    gap = render([ego(x=on_dash + 6.0)], model).segmentation[0]
    assert not bool((gap[60] == SemanticClass.LANE_MARKING).any())
    # the solid edge lines and the ground beyond are there whatever x
    assert bool((gap == SemanticClass.ROAD_EDGE).any())
    assert bool((gap == SemanticClass.OFFROAD).any())


def test_every_class_gets_its_colour_and_vehicles_are_nearer_than_the_ground():
    model = CameraModel(width=100, height=40)
    rows = [
        ego(x=-4.0),
        [25.0, MID, 0.0, 20.0, 4.8, 1.9],
        [15.0, MID + 3.7, -0.6, 20, 4.8, 1.9],
    ]
    frame = render(rows, model)
    seg = frame.segmentation[0]
    assert {int(c) for c in seg.unique()} == {int(c) for c in SemanticClass}
    palette = torch.tensor(PALETTE)
    flat_rgb = frame.rgb[0].permute(1, 2, 0)
    for cls in SemanticClass:
        if cls != SemanticClass.VEHICLE:
            assert torch.all(flat_rgb[seg == cls] == palette[cls])
    # vehicle faces are shaded: rear 1, sides 0.7 (the one cutting in shows one)
    shades = (flat_rgb[seg == SemanticClass.VEHICLE][:, 0] / palette[4, 0]).unique()
    assert torch.allclose(shades, torch.tensor([0.7, 1.0]), atol=1e-6)
    ground = RayCastCamera(ROAD, model)(VehicleState.from_rows([ego(x=-4.0)]))
    hit = seg == SemanticClass.VEHICLE
    assert torch.all(frame.depth[0][hit] < ground.depth[0][hit])


def test_a_truck_seen_from_below_its_roof_and_a_car_seen_from_above():
    # A camera 4 m up sees the roof of a 1.5 m car ahead.
    model = CameraModel(width=40, height=20, hfov=90.0, pitch=20.0, mount_height=4.0)
    frame = render([ego(), [12.0, MID, 0.0, 0.0, 4.8, 1.9]], model)
    seg, red = frame.segmentation[0], frame.rgb[0, 0]
    roof = red[seg == SemanticClass.VEHICLE].max()
    assert roof.item() == pytest.approx(PALETTE[SemanticClass.VEHICLE][0] * 1.3, 1e-6)


def test_a_rotated_ego_sees_the_world_turn_the_other_way():
    box = [20.0, MID, 0.0, 20.0, 4.8, 1.9]
    straight = render([ego(), box]).segmentation[0] == SemanticClass.VEHICLE
    turned = render([ego(heading=0.1), box]).segmentation[0] == SemanticClass.VEHICLE
    cols = torch.arange(40).float()
    centre = (straight.float().sum(0) * cols).sum() / straight.sum()
    centre_turned = (turned.float().sum(0) * cols).sum() / turned.sum()
    assert centre_turned > centre + 1  # turned left: the box moves right


def test_a_rollouts_image_is_the_same_alone_in_a_batch_and_in_slices(monkeypatch):
    state = _random_batch(7)
    camera = RayCastCamera(ROAD, CameraModel(width=30, height=12), heights=[1.5] * 4)
    whole = camera(state)
    assert bool((whole.segmentation == SemanticClass.VEHICLE).any())
    for i in (0, 4):
        alone = camera(state[i : i + 1])
        for name in ("depth", "segmentation", "rgb"):
            assert torch.equal(getattr(alone, name)[0], getattr(whole, name)[i])
    monkeypatch.setattr(raycast, "EAGER_CHUNK_ELEMENTS", 3 * 30 * 12 * 2)
    sliced = camera(state)
    for name in ("depth", "segmentation", "rgb"):
        assert torch.equal(getattr(sliced, name), getattr(whole, name))


def test_an_ego_alone_is_rendered_and_heights_must_match_the_vehicles():
    frame = render([ego()])
    assert not bool((frame.segmentation == SemanticClass.VEHICLE).any())
    with pytest.raises(ValueError, match="heights for 3 vehicles"):
        render([ego(), ego(x=20.0)], heights=[1.5, 1.5, 1.5])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"hfov": 180.0}, "hfov"),
        ({"pitch": 50.0}, "pitch"),
        ({"width": 0}, "image size"),
        ({"mount_height": 0.0}, "mount_height"),
    ],
)
def test_a_camera_model_rejects_impossible_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CameraModel(**kwargs)


def test_road_paint_rejects_dashes_longer_than_their_period():
    with pytest.raises(ValueError, match="dash_length"):
        RoadPaint(dash_length=13.0, dash_period=12.0)


def _random_batch(b, seed=3):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(b, 4, generator=g) * 60 - torch.tensor([0.0, -10.0, -10.0, -10.0])
    y = torch.rand(b, 4, generator=g) * 11.1
    h = (torch.rand(b, 4, generator=g) - 0.5) * 0.4
    size = torch.tensor([4.8, 1.9]).expand(b, 4, 2)
    return VehicleState(x, y, h, torch.full_like(x, 20.0), size[..., 0], size[..., 1])


@pytest.mark.slow
@pytest.mark.skipif(
    not any(shutil.which(c) for c in ("g++", "c++", "clang++")),
    reason="torch.compile needs a C++ compiler",
)
def test_the_compiled_camera_renders_bit_identical_frames():
    camera = RayCastCamera(ROAD, CameraModel(width=30, height=12), heights=[1.5] * 4)
    state = _random_batch(5)
    eager = camera(state)
    fused = torch.compile(camera, fullgraph=True)(state)
    for name in ("depth", "segmentation", "rgb"):
        assert torch.equal(getattr(fused, name), getattr(eager, name))


@pytest.mark.gpu
@pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device present (CPU-only torch)"
)
def test_the_gpu_renders_the_cpu_frames():
    model = CameraModel(width=30, height=12)
    state = _random_batch(5)
    cpu = RayCastCamera(ROAD, model)(state)
    gpu = RayCastCamera(ROAD, model, device="cuda")(state.to("cuda")).to("cpu")
    assert torch.equal(gpu.segmentation, cpu.segmentation)
    assert torch.equal(gpu.depth, cpu.depth)
    assert torch.equal(gpu.rgb, cpu.rgb)
