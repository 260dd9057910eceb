"""Top-down animation of recorded rollouts."""

from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from avrisk.assembly import RolloutTrace
from avrisk.report.animate import (
    animate_rollouts,
    box_corners,
    save_frame_png,
)
from avrisk.scenario.scene import RoadSpec


def _trace(n_steps: int = 12, crashed: bool = False, label: str = "") -> RolloutTrace:
    t = np.arange(n_steps + 1)[:, None]
    x = np.array([[100.0, 130.0, 90.0]]) + np.array([[20.0, 15.0, 22.0]]) * 0.1 * t
    y = np.broadcast_to(np.array([[5.55, 5.55, 9.25]]), x.shape).copy()
    ttc = np.minimum.accumulate(np.linspace(5.0, 0.4, n_steps + 1))
    return RolloutTrace(
        x=x,
        y=y,
        heading=np.zeros_like(x),
        speed=np.broadcast_to(np.array([[20.0, 15.0, 22.0]]), x.shape).copy(),
        length=np.array([4.8, 4.8, 12.0]),
        width=np.array([1.9, 1.9, 2.5]),
        ttc_so_far=ttc,
        n_frames=n_steps + 1 - (4 if crashed else 0),
        crashed=crashed,
        label=label,
    )


def test_box_corners_of_an_axis_aligned_and_a_rotated_box():
    c = box_corners(
        np.array(0.0), np.array(0.0), np.array(0.0), np.array(4.0), np.array(2.0)
    )
    np.testing.assert_allclose(c, [[2, 1], [-2, 1], [-2, -1], [2, -1]])
    r = box_corners(
        np.array(1.0), np.array(1.0), np.array(np.pi / 2), np.array(4.0), np.array(2.0)
    )
    np.testing.assert_allclose(r, [[0, 3], [0, -1], [2, -1], [2, 3]], atol=1e-12)


def test_animation_of_two_rollouts_is_a_gif_with_one_frame_per_step(tmp_path):
    road = RoadSpec()
    out = animate_rollouts(
        [_trace(label="row 0"), _trace(crashed=True, label="row 1")],
        road,
        dt=0.1,
        out=tmp_path / "a.gif",
        fps=10,
    )
    with Image.open(out) as im:
        assert im.format == "GIF" and im.n_frames == 13
        width, height = im.size
    assert width > 2 * height / 2  # two stacked panels, each wide and low
    assert not list(tmp_path.glob(".*tmp"))


def test_a_frame_png_shows_the_ego_in_its_highlight_colour(tmp_path):
    out = save_frame_png([_trace()], RoadSpec(), 0.1, tmp_path / "f.png")
    rgb = np.asarray(Image.open(out).convert("RGB")).reshape(-1, 3).astype(int)
    ego = np.array([0xF2, 0x8E, 0x2B])
    assert (np.abs(rgb - ego).sum(axis=1) < 10).sum() > 50


def test_animating_nothing_is_an_error(tmp_path):
    with pytest.raises(ValueError, match="at least one"):
        animate_rollouts([], RoadSpec(), 0.1, tmp_path / "a.gif")


def test_the_vehicle_hit_is_outlined_red(tmp_path):
    crash_red = np.array([0xD6, 0x27, 0x28])

    def red_pixels(trace, name):
        out = save_frame_png([trace], RoadSpec(), 0.1, tmp_path / name, step=0)
        rgb = np.asarray(Image.open(out).convert("RGB")).reshape(-1, 3).astype(int)
        return (np.abs(rgb - crash_red).sum(axis=1) < 60).sum()

    plain = _trace()
    assert red_pixels(plain, "plain.png") == 0
    assert red_pixels(replace(plain, hit=1), "hit.png") > 20
