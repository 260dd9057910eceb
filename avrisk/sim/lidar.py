"""Ray casting from vehicle centres: lidar ranges, range-rates and hit ids.

Every vehicle carries a planar lidar at its centre with ``R`` beams uniformly
spaced over a full turn, beam 0 straight ahead and the others counter-clockwise
(beam ``k`` at ``2 pi k / R`` from the heading). A beam stops at the first
rectangle edge of *another* vehicle or at a road edge (the road edges are
opaque walls: a vehicle beyond one is not seen). Beams that hit nothing within
``max_range`` read ``max_range``.

The same primitive, :func:`nearest_box`, serves the ego's time-to-collision
rays (:mod:`avrisk.safety.ttc`). Rays are tested against each box in the box's
own frame (slab test, :func:`avrisk.sim.geometry.ray_box_distance`), all
vehicles, beams and rollouts at once, one other vehicle at a time: the cost is
``B * A * (A - 1) * R`` ray-box tests, nothing of size ``B^2``, and no
temporary larger than ``B * A * R``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from avrisk.sim.geometry import (
    capped_reciprocal,
    hit_or_inf,
    min_argmin,
    ray_box_distance,
    step,
    to_local,
)
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.mathops import sincos
from avrisk.tensors.tensors import TensorDataclass

__all__ = [
    "LidarScan",
    "beam_directions",
    "lidar_scan",
    "nearest_box",
    "others_index",
    "relative_velocity",
    "scan_boxes",
]


@dataclass(frozen=True)
class LidarScan(TensorDataclass):
    """One lidar sweep of every vehicle.

    Attributes
    ----------
    range : Tensor of shape (B, A, R)
        Distance from the vehicle centre to the first hit [m]; ``max_range``
        when nothing is hit.
    range_rate : Tensor of shape (B, A, R)
        Relative velocity of the hit vehicle (its velocity minus the sensing
        vehicle's) projected on the beam [m/s]; negative when closing; 0 for a
        road edge or nothing.
    hit : Tensor of int64, shape (B, A, R)
        Index along ``A`` of the vehicle hit; -1 for a road edge or nothing.
    """

    range: Tensor  # [B, A, R] m
    range_rate: Tensor  # [B, A, R] m/s
    hit: Tensor  # [B, A, R] int64


def beam_directions(
    n: int, *, dtype: torch.dtype = torch.float32, device: str | torch.device = "cpu"
) -> tuple[Tensor, Tensor]:
    """Unit directions of ``n`` beams over a full turn, in the sensor's frame.

    Parameters
    ----------
    n : int
        Number of beams ``R``.
    dtype : torch.dtype, default=torch.float32
    device : str or torch.device, default="cpu"

    Returns
    -------
    cos, sin : Tensor of shape (R,)
        Beam ``k`` is at angle ``2 pi k / n`` [rad] counter-clockwise from ahead.
        Computed in float64 with :func:`~avrisk.tensors.mathops.sincos`, then
        rounded, so the table is identical on every machine.
    """
    angles = torch.arange(n, dtype=torch.float64) * (2.0 * math.pi / n)
    s, c = sincos(angles)
    return c.to(dtype=dtype, device=device), s.to(dtype=dtype, device=device)


def others_index(n_vehicles: int, *, device: str | torch.device = "cpu") -> Tensor:
    """Indices of the other vehicles, ``others[a] = [j for j in range(A) if j != a]``.

    Returns
    -------
    Tensor of int64, shape (A, A - 1)
    """
    k = torch.arange(n_vehicles - 1, device=device)
    a = torch.arange(n_vehicles, device=device).unsqueeze(-1)
    return k + (k >= a).to(torch.int64)


def scan_boxes(
    ox: Tensor,
    oy: Tensor,
    oc: Tensor,
    os: Tensor,
    tx: Tensor,
    ty: Tensor,
    tc: Tensor,
    ts: Tensor,
    thl: Tensor,
    thw: Tensor,
    ray_cos: Tensor,
    ray_sin: Tensor,
    max_range: float,
) -> Tensor:
    """Distances along a fan of rays from sensors to a set of boxes.

    Parameters
    ----------
    ox, oy : Tensor of shape (..., 1)
        Sensor position [m].
    oc, os : Tensor of shape (..., 1)
        Cosine and sine of the sensor heading (the rays' reference).
    tx, ty : Tensor of shape (..., J)
        Target box centres [m].
    tc, ts : Tensor of shape (..., J)
        Cosine and sine of the target headings.
    thl, thw : Tensor of shape (..., J)
        Target half-lengths and half-widths [m].
    ray_cos, ray_sin : Tensor of shape (R,)
        Ray directions in the sensor frame.
    max_range : float
        Hits at or beyond this distance [m] are misses.

    Returns
    -------
    Tensor of shape (..., J, R)
        Distance along each ray to each box [m]; ``inf`` on a miss.
    """
    lx, ly = to_local(ox, oy, tx, ty, tc, ts)
    # Sensor heading relative to each target: rotates the ray fan into the
    # target frame with two products per ray instead of a trig call.
    cos_rel = (oc * tc + os * ts).unsqueeze(-1)
    sin_rel = (os * tc - oc * ts).unsqueeze(-1)
    ux = cos_rel * ray_cos - sin_rel * ray_sin
    uy = sin_rel * ray_cos + cos_rel * ray_sin
    return ray_box_distance(
        lx.unsqueeze(-1),
        ly.unsqueeze(-1),
        ux,
        uy,
        thl.unsqueeze(-1),
        thw.unsqueeze(-1),
        max_range,
    )


def nearest_box(
    ox: Tensor,
    oy: Tensor,
    oc: Tensor,
    os: Tensor,
    tx: Tensor,
    ty: Tensor,
    tc: Tensor,
    ts: Tensor,
    thl: Tensor,
    thw: Tensor,
    ray_cos: Tensor,
    ray_sin: Tensor,
    max_range: float,
    one_at_a_time: bool | None = None,
) -> tuple[Tensor, Tensor]:
    """Distance along each ray to the nearest of ``J >= 1`` boxes, and which box.

    Parameters
    ----------
    ox, oy, oc, os, tx, ty, tc, ts, thl, thw, ray_cos, ray_sin, max_range
        As for :func:`scan_boxes`.
    one_at_a_time : bool, optional
        Scan the boxes one at a time, keeping the running minimum and its
        index, instead of all at once followed by
        :func:`avrisk.sim.geometry.min_argmin`. Default: when compiling
        (``torch.compiler.is_compiling()``). The values are the same bit for
        bit either way (``tests/sim/test_lidar.py``).

    Returns
    -------
    distance : Tensor of shape (..., R)
        Distance along each ray to the first box it hits [m]; ``inf`` when it
        hits none within ``max_range``.
    index : Tensor of int64, shape (..., R)
        The box hit first, ``0 <= index < J``: the lowest on a tie, 0 when
        the ray hits none.

    Notes
    -----
    Compiled, one box at a time makes no ``(..., J, R)`` temporary, and the
    scan and the reduction fuse into one loop over ``(..., R)``, which is
    faster than the all-boxes form (BENCHMARKS.md, "The lidar's reduction
    fused, and freed memory kept"). Eager,
    it dispatches ``J`` times as many operations, which pays only where the
    ``(..., J, R)`` temporaries would leave the cache: the simulator's lidar
    chooses by batch size (:class:`avrisk.sim.Simulator`).
    The running index is float arithmetic, ``i + [d_k < d] (k - i)``, exact
    for ``J < 2**24``; distances are capped at the largest finite float for
    the comparison, so that two misses (``inf - inf``) are no improvement.
    """
    scan_args = (ox, oy, oc, os, tx, ty, tc, ts, thl, thw, ray_cos, ray_sin)
    if one_at_a_time is None:
        one_at_a_time = torch.compiler.is_compiling()
    if not one_at_a_time:
        return min_argmin(scan_boxes(*scan_args, max_range), dim=-2)
    big = torch.finfo(ox.dtype).max

    def scan(k: int) -> Tensor:
        box = slice(k, k + 1)
        targets = [t[..., box] for t in (tx, ty, tc, ts, thl, thw)]
        return scan_boxes(
            ox, oy, oc, os, *targets, ray_cos, ray_sin, max_range
        ).squeeze(-2)  # (..., R)

    nearest = scan(0)
    index = torch.zeros_like(nearest)
    for k in range(1, tx.shape[-1]):
        d = scan(k)
        closer = step(nearest.clamp_max(big) - d.clamp_max(big))
        nearest = torch.minimum(nearest, d)
        index = index + closer * (k - index)
    return nearest, index.to(torch.int64)


def relative_velocity(
    oc: Tensor, os: Tensor, ov: Tensor, tc: Tensor, ts: Tensor, tv: Tensor
) -> tuple[Tensor, Tensor]:
    """Velocity of targets relative to a sensor, in the sensor frame.

    Parameters
    ----------
    oc, os, ov : Tensor of shape (..., 1)
        Sensor heading cosine, sine and speed [m/s].
    tc, ts, tv : Tensor of shape (..., J)
        Target heading cosines, sines and speeds [m/s].

    Returns
    -------
    wx, wy : Tensor of shape (..., J)
        Target velocity minus sensor velocity, along and across the sensor
        heading [m/s].
    """
    wx = tv * tc - ov * oc
    wy = tv * ts - ov * os
    return oc * wx + os * wy, oc * wy - os * wx


def lidar_scan(
    state: VehicleState,
    cos: Tensor,
    sin: Tensor,
    road: Road,
    beam_cos: Tensor,
    beam_sin: Tensor,
    max_range: float,
    one_at_a_time: bool | None = None,
) -> LidarScan:
    """Lidar sweep of every vehicle against the others and the road edges.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A) with ``A >= 1`` (the simulator uses (B, A)).
    cos, sin : Tensor of shape (..., A)
        Cosine and sine of ``state.heading``.
    road : Road
        Provides the two road edges ``y = 0`` and ``y = road.width``.
    beam_cos, beam_sin : Tensor of shape (R,)
        Beam directions in the vehicle frame (:func:`beam_directions`).
    max_range : float
        Sensor range [m].
    one_at_a_time : bool, optional
        How the other vehicles are scanned (:func:`nearest_box`): the same
        values either way.

    Returns
    -------
    LidarScan
        Fields of shape (..., A, R).
    """
    n = state.n_vehicles
    y = state.y.unsqueeze(-1)  # (..., A, 1)
    # Road edges, the lines y = 0 and y = W: distance to the nearest one ahead
    # along each beam (branch-free, see ray_box_distance for why).
    beam_sin_world = sin.unsqueeze(-1) * beam_cos + cos.unsqueeze(-1) * beam_sin
    inv = capped_reciprocal(beam_sin_world)
    wall = torch.minimum(_ahead(-y * inv), _ahead((road.width - y) * inv))
    wall = torch.clamp_max(wall, max_range)  # (..., A, R)
    if n == 1:
        zeros = torch.zeros_like(wall)
        return LidarScan(range=wall, range_rate=zeros, hit=zeros.long() - 1)

    others = others_index(n, device=state.x.device)  # (A, A-1)

    def tgt(t: Tensor) -> Tensor:
        return t[..., others]  # (..., A, A-1)

    def src(t: Tensor) -> Tensor:
        return t.unsqueeze(-1)  # (..., A, 1)

    tc, ts = tgt(cos), tgt(sin)
    nearest, j = nearest_box(
        src(state.x),
        y,
        src(cos),
        src(sin),
        tgt(state.x),
        tgt(state.y),
        tc,
        ts,
        0.5 * tgt(state.length),
        0.5 * tgt(state.width),
        beam_cos,
        beam_sin,
        max_range,
        one_at_a_time,
    )  # (..., A, R)
    seen = step(wall - nearest)  # 1.0 for a vehicle; a tie goes to the wall
    wx, wy = relative_velocity(
        src(cos), src(sin), src(state.speed), tc, ts, tgt(state.speed)
    )
    rate = wx.gather(-1, j) * beam_cos + wy.gather(-1, j) * beam_sin
    # others[a, k] = k + (k >= a): the k-th other vehicle of vehicle a.
    hit_id = j + (j >= torch.arange(n, device=j.device).unsqueeze(-1)).to(torch.int64)
    seen_id = seen.to(torch.int64)
    return LidarScan(
        range=torch.minimum(nearest, wall),
        range_rate=rate * seen,
        hit=(hit_id + 1) * seen_id - 1,
    )


def _ahead(t: Tensor) -> Tensor:
    """``t`` where ``t > 0``, else ``inf`` (branch-free; ``t`` finite or inf)."""
    return hit_or_inf(t, step(t))
