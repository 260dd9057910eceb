"""Camera videos of failures: the ego camera's images of a recorded rollout."""

import numpy as np
import pytest
from PIL import Image

from avrisk.assembly import camera_frames
from avrisk.assembly.traces import RolloutTrace
from avrisk.render import CameraModel, RayCastCamera
from avrisk.report.animate import animation_steps
from avrisk.report.camera_video import animate_camera_rollout
from avrisk.sim import Road
from avrisk.sim.camera import SemanticClass
from avrisk.sim.state import VehicleState

ROAD = Road(n_lanes=3, lane_width=3.7, length=500.0)


def _trace(n_frames=12):
    """The ego in the middle lane; a car 20 m ahead that falls 5 m behind per step."""
    t = np.arange(n_frames)[:, None]
    ego_x = 100.0 + 10.0 * t[:, 0]
    other_x = ego_x + 20.0 - 5.0 * t[:, 0]
    lane_y = 1.5 * ROAD.lane_width
    return RolloutTrace(
        x=np.stack([ego_x, other_x], axis=1),
        y=np.full((n_frames, 2), lane_y),
        heading=np.zeros((n_frames, 2)),
        speed=np.full((n_frames, 2), 10.0),
        length=np.array([4.8, 4.8]),
        width=np.array([1.9, 1.9]),
        ttc_so_far=np.full(n_frames, np.inf),
        n_frames=n_frames,
        crashed=False,
        label="hand-built",
    )


@pytest.fixture(scope="module")
def camera():
    return RayCastCamera(ROAD, CameraModel(width=30, height=12), heights=[1.5, 1.5])


def test_each_recorded_step_is_rendered_as_the_camera_renders_that_state(camera):
    trace = _trace()
    frames = camera_frames(trace, camera)
    assert frames.rgb.shape == (12, 12, 30, 3)
    assert frames.depth.shape == frames.segmentation.shape == (12, 12, 30)
    step = 2
    state = VehicleState.from_rows(
        [[trace.x[step, j], trace.y[step, j], 0.0, 10.0, 4.8, 1.9] for j in range(2)]
    )
    alone = camera(state)
    assert np.array_equal(frames.segmentation[step], alone.segmentation[0].numpy())
    assert np.array_equal(frames.depth[step], alone.depth[0].numpy())
    assert np.array_equal(frames.rgb[step], alone.rgb[0].permute(1, 2, 0).numpy())


def test_the_car_ahead_is_seen_until_it_falls_behind(camera):
    frames = camera_frames(_trace(), camera)
    vehicle = (frames.segmentation == SemanticClass.VEHICLE).any(axis=(1, 2))
    # 20 m ahead at step 0, 0 m (level) at step 4, behind after.
    assert vehicle[:3].all() and not vehicle[5:].any()
    # Nearer each step while ahead: the nearest vehicle pixel's depth falls.
    near = [
        frames.depth[i][frames.segmentation[i] == SemanticClass.VEHICLE].min()
        for i in range(3)
    ]
    assert near[0] > near[1] > near[2]


def test_the_video_has_one_frame_per_shown_step(camera, tmp_path):
    trace = _trace()
    frames = camera_frames(trace, camera)
    out = animate_camera_rollout(trace, frames, ROAD, 0.1, tmp_path / "v.gif", stride=2)
    with Image.open(out) as gif:
        # steps 0, 2, ..., 10 and the last, 11
        assert gif.n_frames == len(animation_steps(12, 0.1, 10, 2)) == 7
    assert not list(tmp_path.glob(".*tmp"))


def test_images_of_another_rollout_are_refused(camera, tmp_path):
    frames = camera_frames(_trace(12), camera)
    with pytest.raises(ValueError, match="11 recorded steps"):
        animate_camera_rollout(_trace(11), frames, ROAD, 0.1, tmp_path / "v.gif")
    assert not (tmp_path / "v.gif").exists()
