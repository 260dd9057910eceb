"""Camera videos of recorded rollouts: what a vision ego saw, beside the top-down view.

For a scenario whose ego has a camera (``highway_vision``), a failure's
animation shows, frame by frame, the ego camera's RGB image (the vision
policy's input), its depth [m] and its semantic segmentation side by side,
above the top-down view of :mod:`avrisk.report.animate`. The images are those
of :func:`avrisk.assembly.trace_camera.camera_frames`, rendered again from the
recorded trace.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from avrisk.assembly.trace_camera import SEGMENT_CLASSES, CameraFrames
from avrisk.assembly.traces import RolloutTrace
from avrisk.report.animate import (
    RoadLike,
    TopDownPanel,
    animation_steps,
    play,
    pyplot,
    top_down_height,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["SEGMENT_COLOURS", "animate_camera_rollout"]

#: Colour of each segmentation class in the segmentation view, by name (not
#: the rendered colours: classes a viewer tells apart at a glance).
SEGMENT_COLOURS = {
    "sky": "#c6dbef",
    "road": "#636363",
    "lane marking": "#ffffff",
    "road edge": "#fdae6b",
    "vehicle": "#d62728",
    "offroad": "#74c476",
}


class _CameraPanels:
    """RGB, depth and segmentation images of one rollout, updated frame by frame."""

    def __init__(self, fig: Figure, grid: object, frames: CameraFrames, far: float):
        from matplotlib.colors import ListedColormap
        from matplotlib.patches import Patch

        self.frames = frames
        axes = [fig.add_subplot(grid[0, j]) for j in range(3)]
        for ax in axes:
            ax.set_xticks([])
            ax.set_yticks([])
        self.rgb = axes[0].imshow(frames.rgb[0], interpolation="nearest")
        axes[0].set_title("ego camera (the policy's input)", fontsize=8, loc="left")
        self.depth = axes[1].imshow(
            np.minimum(frames.depth[0], far),
            cmap="magma",
            vmin=0.0,
            vmax=far,
            interpolation="nearest",
        )
        axes[1].set_title(f"depth, 0-{far:g} m (dark: near)", fontsize=8, loc="left")
        classes = SEGMENT_CLASSES  # in label order
        self.segmentation = axes[2].imshow(
            frames.segmentation[0],
            cmap=ListedColormap([SEGMENT_COLOURS[c] for c in classes]),
            vmin=-0.5,
            vmax=len(classes) - 0.5,
            interpolation="nearest",
        )
        axes[2].set_title("segmentation", fontsize=8, loc="left")
        axes[2].legend(
            handles=[
                Patch(
                    facecolor=SEGMENT_COLOURS[c],
                    edgecolor="#404040",
                    label=c,
                )
                for c in classes
            ],
            fontsize=6,
            loc="center left",
            bbox_to_anchor=(1.02, 0.5),
            frameon=False,
        )
        self.far = far

    def draw(self, k: int) -> None:
        i = min(k, self.frames.depth.shape[0] - 1)
        self.rgb.set_data(self.frames.rgb[i])
        self.depth.set_data(np.minimum(self.frames.depth[i], self.far))
        self.segmentation.set_data(self.frames.segmentation[i])


def animate_camera_rollout(
    trace: RolloutTrace,
    frames: CameraFrames,
    road: RoadLike,
    dt: float,
    out: str | Path,
    *,
    fps: int = 10,
    view_length: float = 120.0,
    far: float = 100.0,
    stride: int | None = None,
) -> Path:
    """Write a GIF of one rollout: camera RGB, depth and segmentation over top-down.

    Parameters
    ----------
    trace : RolloutTrace
    frames : CameraFrames
        The ego camera's images of ``trace`` (:func:`avrisk.assembly.camera_frames`).
    road : RoadLike
        Lane count, lane width [m] and length [m].
    dt : float
        Simulator time step [s].
    out : str or pathlib.Path
        GIF file to write (written to a temporary name, then renamed).
    fps : int, default=10
        Frames per second of the GIF.
    view_length : float, default=120.0
        Length of road shown around the ego in the top-down view [m].
    far : float, default=100.0
        Depth shown as the far end of the colour scale [m] (beyond, and sky,
        alike).
    stride : int or None
        Show every ``stride``-th step; default chooses real time at ``fps``.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    ValueError
        If ``frames`` does not hold one image per recorded step of ``trace``.
    """
    if frames.depth.shape[0] != trace.n_frames:
        raise ValueError(
            f"{frames.depth.shape[0]} camera images for a trace of "
            f"{trace.n_frames} recorded steps"
        )
    width_in = 10.0
    road_h = top_down_height(road, view_length, width_in)
    image_h = (width_in / 3.6) * frames.depth.shape[1] / frames.depth.shape[2] + 0.35
    fig = pyplot().figure(figsize=(width_in, image_h + road_h))
    grid = fig.add_gridspec(
        2, 3, height_ratios=[image_h, road_h], width_ratios=[1.0, 1.0, 1.0]
    )
    cameras = _CameraPanels(fig, grid, frames, far)
    top_down = fig.add_subplot(grid[1, :])
    panel = TopDownPanel(top_down, trace, road, view_length)
    top_down.set_xlabel("x along the road [m]   (ego orange)", fontsize=8)
    fig.tight_layout(pad=0.5, h_pad=0.6, w_pad=0.4, rect=(0.0, 0.0, 0.92, 1.0))

    def draw(k: int) -> None:
        cameras.draw(k)
        panel.draw(k, dt)

    return play(fig, animation_steps(trace.n_frames, dt, fps, stride), draw, fps, out)
