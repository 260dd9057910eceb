"""A batched ray caster: the ego's camera image of every rollout at once.

Every pixel's centre ray (:mod:`avrisk.render.rays`) is intersected, for all
``B`` rollouts and ``P = H W`` pixels at once, with

* the ground plane ``z = 0`` (analytically: ``t = mount_height / -r_z``), then
  classified by where it lands: road, lane marking, road edge line, or the
  ground beyond the edges (:class:`RoadPaint`);
* every other vehicle as a 3-D box, its rectangle extruded from the ground to
  its height (slab test, as :func:`avrisk.sim.geometry.ray_box_distance` in
  2-D, plus the vertical slab);

and the nearest hit wins: depth along the optical axis [m], a
:class:`~avrisk.sim.camera.SemanticClass`, and a colour from the class
(:data:`PALETTE`; vehicle faces shaded by which side is seen). Rays above the
horizon that hit nothing are sky.

Every operation is elementwise along the batch (or a ``min`` over vehicles,
which is exact), and only ``+ - * /`` and comparisons touch the rollouts'
numbers (the ego's heading goes through :func:`avrisk.tensors.mathops.sincos`),
so a rollout's image is bit-identical alone, in any batch, and in slices. One
code path for CPU and GPU; under ``torch.compile`` the whole frame is one
fused graph. Eager mode on a CPU renders large batches in slices of about
:data:`EAGER_CHUNK_ELEMENTS` (ray, box) pairs, which keeps the temporaries
cache-sized (:mod:`avrisk.tensors.slices`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import torch
from torch import Tensor

from avrisk.render.rays import CameraModel
from avrisk.sim.camera import CameraFrame, SemanticClass
from avrisk.sim.geometry import capped_reciprocal, hit_or_inf, min_argmin, step
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.mathops import sincos
from avrisk.tensors.slices import in_slices

__all__ = ["DEFAULT_VEHICLE_HEIGHT", "PALETTE", "RayCastCamera", "RoadPaint"]

#: Height of a vehicle box when none is given [m] (a passenger car).
DEFAULT_VEHICLE_HEIGHT = 1.5

#: Colour of each :class:`SemanticClass`, RGB in [0, 1], indexed by the class.
PALETTE: tuple[tuple[float, float, float], ...] = (
    (0.53, 0.75, 0.92),  # SKY
    (0.35, 0.35, 0.37),  # ROAD
    (0.92, 0.92, 0.92),  # LANE_MARKING
    (0.95, 0.85, 0.30),  # ROAD_EDGE
    (0.70, 0.12, 0.12),  # VEHICLE (its rear or front face)
    (0.30, 0.45, 0.22),  # OFFROAD
)
#: Brightness of a vehicle's sides and roof relative to its rear/front face.
_SIDE_SHADE, _ROOF_SHADE = 0.7, 1.3

#: Pairs of (ray, box) per eager slice of the batch.
EAGER_CHUNK_ELEMENTS = 1 << 19


@dataclass(frozen=True)
class RoadPaint:
    """The markings painted on the road (US practice: 10 ft dashes, 30 ft gaps).

    Parameters
    ----------
    line_width : float, default=0.15
        Width of every painted line [m].
    dash_length : float, default=3.0
        Length of a dash of the lines between lanes [m].
    dash_period : float, default=12.0
        Dash plus gap [m]; dashes cover ``x mod dash_period < dash_length``
        in road coordinates, so they stay put on the road as the ego moves.
    """

    line_width: float = 0.15  # [m]
    dash_length: float = 3.0  # [m]
    dash_period: float = 12.0  # [m]

    def __post_init__(self) -> None:
        if not self.line_width > 0:
            raise ValueError(f"line_width must be > 0 [m]; got {self.line_width}")
        if not 0 < self.dash_length <= self.dash_period:
            raise ValueError(
                "need 0 < dash_length <= dash_period [m]; got "
                f"{self.dash_length} and {self.dash_period}"
            )

    def classify(self, x: Tensor, y: Tensor, road: Road) -> Tensor:
        """What lies on the ground at road coordinates ``(x, y)``.

        Parameters
        ----------
        x, y : Tensor of shape (...)
            Points on the ground [m] (see :mod:`avrisk.sim.road`).
        road : Road

        Returns
        -------
        Tensor of int8, shape (...)
            ``ROAD``, ``LANE_MARKING``, ``ROAD_EDGE`` (the solid line inside
            either edge) or ``OFFROAD`` (:class:`SemanticClass`).
        """
        w, lw = self.line_width, road.lane_width
        nearest = torch.clamp(torch.round(y / lw), 1, max(1, road.n_lanes - 1))
        on_line = torch.abs(y - nearest * lw) < 0.5 * w
        phase = x - torch.floor(x / self.dash_period) * self.dash_period
        dashed = on_line & (phase < self.dash_length) & (road.n_lanes > 1)
        edge = (y < w) | (y > road.width - w)
        outside = (y < 0) | (y > road.width)
        cls = torch.full_like(y, int(SemanticClass.ROAD), dtype=torch.int8)
        cls = torch.where(dashed, int(SemanticClass.LANE_MARKING), cls)
        cls = torch.where(edge, int(SemanticClass.ROAD_EDGE), cls)
        return torch.where(outside, int(SemanticClass.OFFROAD), cls).to(torch.int8)


class RayCastCamera:
    """The ego's front camera, rendered by ray casting (a simulator camera).

    Implements :class:`avrisk.sim.camera.Camera`: ``camera(state)`` gives the
    :class:`~avrisk.sim.camera.CameraFrame` of vehicle 0 of every rollout.

    Parameters
    ----------
    road : Road
    model : CameraModel, optional
        Default ``CameraModel()`` (PilotNet's 66 x 200 pixels).
    heights : sequence of float, optional
        Height of each of the ``A`` vehicle boxes [m] (slot 0, the ego, is not
        drawn); default :data:`DEFAULT_VEHICLE_HEIGHT` for every vehicle.
    paint : RoadPaint, default=RoadPaint()
    device : str or torch.device, default="cpu"
    dtype : torch.dtype, default=torch.float32

    Examples
    --------
    >>> cam = RayCastCamera(Road(n_lanes=3), CameraModel(width=8, height=4))
    >>> ego = VehicleState.from_rows([[0.0, 5.55, 0.0, 20.0, 4.8, 1.9]])
    >>> frame = cam(ego)
    >>> tuple(frame.rgb.shape), tuple(frame.depth.shape)
    ((1, 3, 4, 8), (1, 4, 8))
    >>> frame.segmentation[0, 0].tolist() == [int(SemanticClass.SKY)] * 8
    True
    """

    def __init__(
        self,
        road: Road,
        model: CameraModel | None = None,
        *,
        heights: Sequence[float] | None = None,
        paint: RoadPaint = RoadPaint(),
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
    ) -> None:
        model = CameraModel() if model is None else model
        self.road = road
        self.model = model
        self.paint = paint
        self.device = torch.device(device)
        self.dtype = dtype
        rays = model.pixel_rays(dtype=dtype, device=device)
        self._rx, self._ry, self._rz = rays.x, rays.y, rays.z
        h = model.mount_height
        # Ground: depth h / -r_z below the horizon; its point in the ego frame.
        below = rays.z < 0
        t = torch.where(below, h / torch.where(below, -rays.z, 1.0), 0.0)
        self._ground_depth = torch.where(below, t, torch.inf)  # [P]
        self._ground_x = model.forward + t * rays.x  # [P] (0 above the horizon)
        self._ground_y = t * rays.y  # [P]
        self._below = below
        self._iz = capped_reciprocal(rays.z)  # [P]
        self._heights = (
            None
            if heights is None
            else torch.tensor(list(heights), dtype=dtype, device=device)
        )
        self._palette = torch.tensor(PALETTE, dtype=dtype, device=device)

    def __call__(self, state: VehicleState) -> CameraFrame:
        """The ego camera's frames of a state.

        Parameters
        ----------
        state : VehicleState
            Fields of shape (B, A) on the camera's device and dtype; vehicle 0
            carries the camera.

        Returns
        -------
        CameraFrame
            ``depth`` (B, H, W) [m], ``segmentation`` (B, H, W) int8, ``rgb``
            (B, 3, H, W) in [0, 1].
        """
        per_rollout = (state.n_vehicles - 1) * self._ground_depth.shape[0]
        return in_slices(
            self._render, (state,), per_rollout, EAGER_CHUNK_ELEMENTS, state.x.device
        )

    def _heights_of(self, state: VehicleState) -> Tensor:
        """Box height of every vehicle, shape (A,) [m]."""
        if self._heights is None:
            return torch.full_like(state.x[0], DEFAULT_VEHICLE_HEIGHT)
        if self._heights.shape != (state.n_vehicles,):
            raise ValueError(
                f"the camera has heights for {self._heights.shape[0]} vehicles; "
                f"the state has {state.n_vehicles}"
            )
        return self._heights

    def _render(self, state: VehicleState) -> CameraFrame:
        m = self.model
        sin, cos = sincos(state.heading)  # [B, A]
        ce, se = cos[:, :1], sin[:, :1]  # the ego's, [B, 1]
        # Ground: the pixel's point in road coordinates, then what is painted.
        gx = state.x[:, :1] + ce * self._ground_x - se * self._ground_y  # [B, P]
        gy = state.y[:, :1] + se * self._ground_x + ce * self._ground_y
        ground = self.paint.classify(gx, gy, self.road)
        ground = torch.where(self._below, ground, int(SemanticClass.SKY))
        # Vehicles 1..A-1 as boxes, in each box's own frame.
        cam_x = state.x[:, :1] + m.forward * ce  # [B, 1]
        cam_y = state.y[:, :1] + m.forward * se
        cv, sv = cos[:, 1:], sin[:, 1:]  # [B, K]
        dx, dy = cam_x - state.x[:, 1:], cam_y - state.y[:, 1:]
        ox, oy = cv * dx + sv * dy, cv * dy - sv * dx  # [B, K]
        c_rel, s_rel = cv * ce + sv * se, sv * ce - cv * se  # heading difference
        hl, hw = 0.5 * state.length[:, 1:], 0.5 * state.width[:, 1:]
        top = self._heights_of(state)[1:] - m.mount_height  # [K], from the camera
        t_box = _box_depth(
            ox.unsqueeze(-1),
            oy.unsqueeze(-1),
            c_rel.unsqueeze(-1) * self._rx + s_rel.unsqueeze(-1) * self._ry,
            c_rel.unsqueeze(-1) * self._ry - s_rel.unsqueeze(-1) * self._rx,
            self._iz,
            hl.unsqueeze(-1),
            hw.unsqueeze(-1),
            -m.mount_height,
            top.reshape(1, -1, 1),
        )  # [B, K, P]
        if t_box.shape[1] > 0:
            t_vehicle, which = min_argmin(t_box, dim=1)  # [B, P]
        else:
            t_vehicle = torch.full_like(gx, torch.inf)
            which = torch.zeros_like(gx, dtype=torch.int64)
        hit = t_vehicle < self._ground_depth
        depth = torch.where(hit, t_vehicle, self._ground_depth)
        cls = torch.where(hit, int(SemanticClass.VEHICLE), ground).to(torch.int8)
        box = _Boxes(ox, oy, c_rel, s_rel, hl, hw, top)
        shade = torch.where(hit, self._face_shade(t_vehicle, which, box), 1.0)
        rgb = (self._palette[cls.to(torch.int64)] * shade.unsqueeze(-1)).clamp_max(1.0)
        shape = (state.batch_size, m.height, m.width)
        return CameraFrame(
            depth=depth.reshape(shape),
            segmentation=cls.reshape(shape),
            rgb=rgb.reshape(*shape, 3).permute(0, 3, 1, 2).contiguous(),
        )

    def _face_shade(self, t: Tensor, which: Tensor, box: _Boxes) -> Tensor:
        """Brightness of the box face each ray enters, shape (B, P).

        The face is told by the entry point relative to the box's size: the
        roof (:data:`_ROOF_SHADE`), a side (:data:`_SIDE_SHADE`), else the rear
        or front (1). Rays that hit no box get a value that is not used.

        Parameters
        ----------
        t : Tensor of shape (B, P)
            Depth of the nearest box [m] (``inf``: none).
        which : Tensor of int64, shape (B, P)
            Index of that box among the ``K`` others.
        box : _Boxes
            The boxes relative to the camera, fields of shape (B, K) or (K,).
        """
        if box.ox.shape[1] == 0:  # no other vehicle
            return torch.ones_like(t)
        t = torch.where(torch.isfinite(t), t, 0.0)

        def pick(v: Tensor) -> Tensor:
            return torch.gather(v, 1, which)

        c, s = pick(box.c_rel), pick(box.s_rel)
        px = pick(box.ox) + t * (c * self._rx + s * self._ry)
        py = pick(box.oy) + t * (c * self._ry - s * self._rx)
        roof = torch.abs(t * self._rz - box.top[which]) < 1e-3 * (1.0 + t)
        side = torch.abs(py) * pick(box.hl) > torch.abs(px) * pick(box.hw)
        return torch.where(roof, _ROOF_SHADE, torch.where(side, _SIDE_SHADE, 1.0))


class _Boxes(NamedTuple):
    """The other vehicles' boxes seen from the camera (internal).

    ``ox, oy`` (B, K): the camera in each box's frame [m]; ``c_rel, s_rel``
    (B, K): cosine and sine of the box heading minus the ego's; ``hl, hw``
    (B, K): half-length and half-width [m]; ``top`` (K,): box top above the
    camera [m].
    """

    ox: Tensor
    oy: Tensor
    c_rel: Tensor
    s_rel: Tensor
    hl: Tensor
    hw: Tensor
    top: Tensor


def _box_depth(
    ox: Tensor,
    oy: Tensor,
    ux: Tensor,
    uy: Tensor,
    iz: Tensor,
    hl: Tensor,
    hw: Tensor,
    bottom: Tensor | float,
    top: Tensor | float,
) -> Tensor:
    """Depth of a ray's entry into an upright box (3-D slab test, box frame).

    The box is ``[-hl, hl] x [-hw, hw]`` horizontally and ``[bottom, top]``
    vertically, relative to the ray's origin height; the ray starts at
    ``(ox, oy)`` and runs along ``(ux, uy, uz)`` with ``iz = 1 / uz``
    (:func:`~avrisk.sim.geometry.capped_reciprocal`).

    Parameters
    ----------
    ox, oy : Tensor of shape (...)
        Ray origin in the box's horizontal frame [m].
    ux, uy : Tensor of shape (...)
        Horizontal ray direction in the box frame (any length: depths are in
        its units).
    iz : Tensor of shape (...)
        Reciprocal of the vertical ray component.
    hl, hw : Tensor of shape (...)
        Half-length and half-width of the box [m].
    bottom, top : Tensor of shape (...) or float
        Vertical extent of the box relative to the ray's origin [m].

    Returns
    -------
    Tensor of shape (...)
        Ray parameter at the entry point (0 when the origin is inside),
        ``inf`` on a miss (branch-free, as the 2-D version).
    """
    ix, iy = capped_reciprocal(ux), capped_reciprocal(uy)
    tx1, tx2 = (-hl - ox) * ix, (hl - ox) * ix
    ty1, ty2 = (-hw - oy) * iy, (hw - oy) * iy
    tz1, tz2 = bottom * iz, top * iz
    t_enter = torch.relu(
        torch.maximum(
            torch.maximum(torch.minimum(tx1, tx2), torch.minimum(ty1, ty2)),
            torch.minimum(tz1, tz2),
        )
    )
    t_exit = torch.minimum(
        torch.minimum(torch.maximum(tx1, tx2), torch.maximum(ty1, ty2)),
        torch.maximum(tz1, tz2),
    )
    return hit_or_inf(t_enter, step(t_exit - t_enter))
