"""Top-down animations of recorded rollouts (Matplotlib, written as GIF by Pillow).

One panel per rollout, stacked vertically and played in lockstep. Each panel
follows its ego along the road and shows the lanes, every vehicle as an
oriented rectangle (the ego in orange, a short line marking each heading, the
vehicle the ego crashes into outlined red), and a title with the time and the
minimum time-to-collision so far. A rollout that ended early (crash) holds its
last frame, marked in red.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from avrisk.assembly.traces import RolloutTrace, resimulate

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from avrisk.assembly import ScenarioSimulator

FloatArray = NDArray[np.float64]

EGO_COLOUR = "#f28e2b"
OTHER_COLOUR = "#4e79a7"
ROAD_COLOUR = "#d9d9d9"
CRASH_COLOUR = "#d62728"


class RoadLike(Protocol):
    """What the renderer needs of a road (``RoadSpec`` or ``avrisk.sim.road.Road``)."""

    n_lanes: int
    lane_width: float
    length: float


def box_corners(
    x: FloatArray,
    y: FloatArray,
    heading: FloatArray,
    length: FloatArray,
    width: FloatArray,
) -> FloatArray:
    """Corners of oriented rectangles, counter-clockwise from the front left.

    Parameters
    ----------
    x, y, heading, length, width : ndarray of shape (...)
        Centre [m], heading [rad] and size [m].

    Returns
    -------
    ndarray of shape (..., 4, 2)
        Corner coordinates [m].
    """
    c, s = np.cos(heading), np.sin(heading)
    hl, hw = 0.5 * np.asarray(length), 0.5 * np.asarray(width)
    sign_l = np.array([1.0, -1.0, -1.0, 1.0])
    sign_w = np.array([1.0, 1.0, -1.0, -1.0])
    dl = hl[..., None] * sign_l
    dw = hw[..., None] * sign_w
    cx = x[..., None] + dl * c[..., None] - dw * s[..., None]
    cy = y[..., None] + dl * s[..., None] + dw * c[..., None]
    return np.stack([cx, cy], axis=-1)


class TopDownPanel:
    """The top-down view of one rollout on ``ax``, updated in place frame by frame."""

    def __init__(
        self, ax: Axes, trace: RolloutTrace, road: RoadLike, view_length: float
    ):
        from matplotlib.patches import Polygon, Rectangle

        self.ax, self.trace, self.view_length = ax, trace, view_length
        width = road.n_lanes * road.lane_width
        ax.add_patch(
            Rectangle(
                (-1e4, 0.0), 2e4 + road.length, width, color=ROAD_COLOUR, zorder=0
            )
        )
        xs = [-1e4, road.length + 1e4]
        for k in range(road.n_lanes + 1):
            edge = k in (0, road.n_lanes)
            ax.plot(
                xs,
                [k * road.lane_width] * 2,
                color="white" if not edge else "#404040",
                lw=2.0 if edge else 1.0,
                ls="-" if edge else (0, (6, 6)),
                zorder=1,
            )
        ax.axvline(road.length, color="#404040", lw=1.0, ls=":", zorder=1)
        ax.set_ylim(-1.0, width + 1.0)
        # A fixed x-span before layout, so tight_layout sees the final aspect.
        ax.set_xlim(0.0, view_length)
        ax.set_aspect("equal")
        ax.set_yticks([])
        ax.tick_params(axis="x", labelsize=7)
        n_agents = trace.x.shape[1]
        self.boxes = []
        self.noses = []
        for j in range(n_agents):
            colour = EGO_COLOUR if j == 0 else OTHER_COLOUR
            hit = j == trace.hit and j > 0
            poly = Polygon(
                np.zeros((4, 2)),
                closed=True,
                facecolor=colour,
                edgecolor=CRASH_COLOUR if hit else "black",
                lw=1.4 if j == 0 or hit else 0.6,
                zorder=3 if j == 0 else 2,
            )
            ax.add_patch(poly)
            self.boxes.append(poly)
            (nose,) = ax.plot([], [], color="black", lw=0.8, zorder=4)
            self.noses.append(nose)
        self.title = ax.set_title("", fontsize=9, loc="left")

    def draw(self, k: int, dt: float) -> None:
        """Show recorded step ``k`` (the last one after the rollout ended)."""
        tr = self.trace
        i = min(k, tr.n_frames - 1)
        corners = box_corners(tr.x[i], tr.y[i], tr.heading[i], tr.length, tr.width)
        for j, poly in enumerate(self.boxes):
            poly.set_xy(corners[j])
            hx = tr.x[i, j] + 0.5 * tr.length[j] * np.cos(tr.heading[i, j])
            hy = tr.y[i, j] + 0.5 * tr.length[j] * np.sin(tr.heading[i, j])
            self.noses[j].set_data([tr.x[i, j], hx], [tr.y[i, j], hy])
        ended = tr.crashed and k >= tr.n_frames - 1
        self.boxes[0].set_edgecolor(CRASH_COLOUR if ended else "black")
        ego_x = tr.x[i, 0]
        self.ax.set_xlim(
            ego_x - 0.35 * self.view_length, ego_x + 0.65 * self.view_length
        )
        ttc = tr.ttc_so_far[i]
        ttc_text = "inf" if not np.isfinite(ttc) else f"{ttc:.2f} s"
        status = "   CRASH" if ended else ""
        label = f"{tr.label}   " if tr.label else ""
        self.title.set_text(
            f"{label}t = {i * dt:4.1f} s   ego {tr.speed[i, 0]:4.1f} m/s   "
            f"min TTC so far {ttc_text}{status}"
        )
        self.title.set_color(CRASH_COLOUR if ended else "black")


def pyplot() -> Any:
    """``matplotlib.pyplot``, on the file-only Agg backend unless one is chosen."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def top_down_height(road: RoadLike, view_length: float, width_in: float) -> float:
    """Height [in] of a top-down panel ``width_in`` wide showing ``view_length`` m."""
    return width_in * (road.n_lanes * road.lane_width + 2.0) / view_length + 0.55


def _figure(
    traces: Sequence[RolloutTrace], road: RoadLike, view_length: float
) -> tuple[Figure, list[TopDownPanel]]:
    width_in = 10.0
    panel_h = top_down_height(road, view_length, width_in)
    fig, axes = pyplot().subplots(
        len(traces), 1, figsize=(width_in, panel_h * len(traces)), squeeze=False
    )
    panels = [
        TopDownPanel(ax, tr, road, view_length)
        for ax, tr in zip(axes[:, 0], traces, strict=True)
    ]
    hit = "; vehicle hit outlined red" if any(tr.hit > 0 for tr in traces) else ""
    axes[-1, 0].set_xlabel(f"x along the road [m]   (ego orange{hit})", fontsize=8)
    fig.tight_layout(pad=0.5, h_pad=0.8)
    return fig, panels


def _figure_image(fig: Figure) -> Any:
    """The figure drawn, as an RGB PIL image."""
    from PIL import Image

    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    return Image.fromarray(rgba[..., :3].copy())


def animate_rollouts(
    traces: Sequence[RolloutTrace],
    road: RoadLike,
    dt: float,
    out: str | Path,
    *,
    fps: int = 10,
    view_length: float = 120.0,
    stride: int | None = None,
) -> Path:
    """Write a top-down GIF of one or more rollouts played together.

    Parameters
    ----------
    traces : sequence of RolloutTrace
        One panel per trace, top to bottom.
    road : RoadLike
        Lane count, lane width [m] and length [m].
    dt : float
        Simulator time step [s].
    out : str or pathlib.Path
        GIF file to write (written to a temporary name, then renamed).
    fps : int, default=10
        Frames per second of the GIF.
    view_length : float, default=120.0
        Length of road shown around each ego [m].
    stride : int or None
        Show every ``stride``-th step; default chooses real time at ``fps``.

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    if not traces:
        raise ValueError("animate_rollouts needs at least one trace")
    steps = animation_steps(max(tr.n_frames for tr in traces), dt, fps, stride)
    fig, panels = _figure(traces, road, view_length)

    def draw(k: int) -> None:
        for panel in panels:
            panel.draw(k, dt)

    return play(fig, steps, draw, fps, out)


def animation_steps(
    n_frames: int, dt: float, fps: int, stride: int | None
) -> list[int]:
    """Recorded steps an animation shows: every ``stride``-th, and the last.

    ``stride`` None plays real time at ``fps`` (one shown step per ``1 / fps`` s).
    """
    if stride is None:
        stride = max(1, round(1.0 / (fps * dt)))
    steps = list(range(0, n_frames, stride))
    if steps[-1] != n_frames - 1:
        steps.append(n_frames - 1)
    return steps


def play(
    fig: Figure,
    steps: Sequence[int],
    draw: Callable[[int], None],
    fps: int,
    out: str | Path,
) -> Path:
    """Write ``fig`` as a looping GIF, one frame per step, and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    steps : sequence of int
        Recorded steps to show (:func:`animation_steps`).
    draw : callable
        ``draw(k)`` updates the figure's artists to step ``k``.
    fps : int
        Frames per second; the last frame is held a second.
    out : str or pathlib.Path
        GIF file, written to a temporary name, then renamed: a reader never
        sees half a file.

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    frames = []
    try:
        for k in steps:
            draw(k)
            frames.append(_figure_image(fig))
    finally:
        pyplot().close(fig)
    out = Path(out)
    durations = [int(1000 / fps)] * (len(frames) - 1) + [1000]
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        frames[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=frames[1:],
            duration=durations,
            loop=0,
            optimize=False,
        )
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out


def save_frame_png(
    traces: Sequence[RolloutTrace],
    road: RoadLike,
    dt: float,
    out: str | Path,
    *,
    step: int | None = None,
    view_length: float = 120.0,
) -> Path:
    """Save one frame as a PNG (default: when the first trace reaches its min TTC).

    Parameters
    ----------
    traces : sequence of RolloutTrace
    road : RoadLike
    dt : float
        Time step [s].
    out : str or pathlib.Path
        PNG file to write.
    step : int or None
        Step to show; default is the first step reaching the first trace's minimum.
    view_length : float, default=120.0
        Length of road shown around each ego [m].

    Returns
    -------
    pathlib.Path
    """
    out = Path(out)
    if step is None:
        first = traces[0]
        series = first.ttc_so_far[: first.n_frames]
        step = (
            int(np.argmax(series <= first.min_ttc)) if np.isfinite(first.min_ttc) else 0
        )
    fig, panels = _figure(traces, road, view_length)
    try:
        for panel in panels:
            panel.draw(step, dt)
        fig.savefig(out, dpi=100)
    finally:
        pyplot().close(fig)
    return out


def animate_samples(
    sim: ScenarioSimulator, rows: Sequence[Mapping[str, Any]], path: Path
) -> Path:
    """Re-simulate samples-table rows with traces and write a top-down GIF.

    Parameters
    ----------
    sim : avrisk.assembly.ScenarioSimulator
        The scenario the rows were simulated in.
    rows : sequence of mapping
        Samples-table rows: the columns of ``sim.layout`` and ``seed``.
    path : Path
        GIF to write (its folder is created).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    traces = _traces(sim, rows)
    spec = sim.spec
    path.parent.mkdir(parents=True, exist_ok=True)
    animate_rollouts(traces, spec.road, spec.simulation.dt, path)
    return path


def animate_pair(
    sims: Sequence[ScenarioSimulator],
    row: Mapping[str, Any],
    labels: Sequence[str],
    path: Path,
) -> Path:
    """One sample driven by each of several simulators (egos), played in step.

    The same ``X`` and seed in each (common random numbers), one panel per
    simulator, top to bottom, every panel at the same time step in every
    frame: where the egos part is where they differ.

    Parameters
    ----------
    sims : sequence of avrisk.assembly.ScenarioSimulator
        One per ego, of one scenario (the same road and time step).
    row : mapping
        A samples-table row: the columns of each ``sim.layout`` and ``seed``.
    labels : sequence of str
        One per simulator, shown in its panel's title (``"A"``, ``"B"``).
    path : Path
        GIF to write (its folder is created).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    traces = [
        dataclasses.replace(_traces(sim, [row])[0], label=label)
        for sim, label in zip(sims, labels, strict=True)
    ]
    spec = sims[0].spec
    path.parent.mkdir(parents=True, exist_ok=True)
    animate_rollouts(traces, spec.road, spec.simulation.dt, path)
    return path


def _traces(
    sim: ScenarioSimulator, rows: Sequence[Mapping[str, Any]]
) -> list[RolloutTrace]:
    """Samples-table rows simulated again, with their traces."""
    x = np.array([[row[c] for c in sim.layout.columns] for row in rows])
    seeds = np.array([row["seed"] for row in rows], dtype=np.int64)
    return resimulate(sim, x, seeds)[1]
