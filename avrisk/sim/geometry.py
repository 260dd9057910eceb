"""Oriented-rectangle geometry: corners, frames, ray casting, overlap.

Every function is written for one pair (one ray and one box, two boxes) and
broadcasts over any leading dimensions ``(...)``; shapes in the docstrings are
the broadcast shape. Headings enter as their cosine ``c`` and sine ``s`` so the
caller computes them once per step (see :func:`avrisk.tensors.mathops.sincos`).

Conventions
-----------
* A box is centred at ``(x, y)`` with half-length ``hl`` along its heading
  ``(c, s)`` and half-width ``hw`` across it.
* Contact is not collision: two boxes *overlap* only when their interiors
  intersect, so boxes that merely touch along an edge or at a corner do not
  overlap. A ray that only touches a box's corner does not hit it.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = [
    "box_corners",
    "boxes_overlap",
    "capped_reciprocal",
    "hit_or_inf",
    "min_argmin",
    "ray_box_distance",
    "step",
    "to_local",
]


def box_corners(
    x: Tensor, y: Tensor, c: Tensor, s: Tensor, hl: Tensor, hw: Tensor
) -> Tensor:
    """Corners of oriented boxes.

    Parameters
    ----------
    x, y : Tensor of shape (...)
        Centre [m].
    c, s : Tensor of shape (...)
        Cosine and sine of the heading.
    hl, hw : Tensor of shape (...)
        Half-length and half-width [m].

    Returns
    -------
    Tensor of shape (..., 4, 2)
        Front-left, rear-left, rear-right, front-right corners [m]
        (counter-clockwise).
    """
    lx = torch.stack([hl, -hl, -hl, hl], dim=-1)
    ly = torch.stack([hw, hw, -hw, -hw], dim=-1)
    c, s = c.unsqueeze(-1), s.unsqueeze(-1)
    cx = x.unsqueeze(-1) + c * lx - s * ly
    cy = y.unsqueeze(-1) + s * lx + c * ly
    return torch.stack([cx, cy], dim=-1)


def to_local(
    px: Tensor, py: Tensor, x: Tensor, y: Tensor, c: Tensor, s: Tensor
) -> tuple[Tensor, Tensor]:
    """Express points in a box's frame (origin at its centre, ``+x`` along it).

    Parameters
    ----------
    px, py : Tensor of shape (...)
        Points in road coordinates [m].
    x, y : Tensor of shape (...)
        Box centre [m].
    c, s : Tensor of shape (...)
        Cosine and sine of the box heading.

    Returns
    -------
    lx, ly : Tensor of shape (...)
        The points in the box frame [m].
    """
    dx = px - x
    dy = py - y
    return c * dx + s * dy, c * dy - s * dx


def ray_box_distance(
    ox: Tensor,
    oy: Tensor,
    ux: Tensor,
    uy: Tensor,
    hl: Tensor,
    hw: Tensor,
    max_range: float = math.inf,
) -> Tensor:
    """Distance along a ray to the boundary of a box (slab test, box frame).

    The ray and the box are given in the box's own frame, where the box is the
    axis-aligned ``[-hl, hl] x [-hw, hw]``.

    Parameters
    ----------
    ox, oy : Tensor of shape (...)
        Ray origin in the box frame [m].
    ux, uy : Tensor of shape (...)
        Unit ray direction in the box frame.
    hl, hw : Tensor of shape (...)
        Half-length and half-width of the box [m].
    max_range : float, default=inf
        Hits at or beyond this distance [m] count as misses.

    Returns
    -------
    Tensor of shape (...)
        Distance from the origin to the first boundary point on the ray [m];
        ``0`` when the origin is inside the box; ``inf`` when
        the ray misses, points away, or hits at or beyond ``max_range``. A ray
        that touches only a corner misses; one running exactly along an edge
        line may count either way (both are sets of measure zero).

    Notes
    -----
    Branch-free on purpose: this runs on the largest tensors of a step
    (rollouts x vehicles x rays), where ``torch.where`` and boolean masks cost
    ten times more than arithmetic on CPU. Reciprocals of zero direction
    components are capped at the largest finite float, so ``0 * inf`` (an
    origin exactly on a slab boundary) cannot make a NaN. The miss test
    ``t_enter < t_exit`` becomes a 0/1 factor ``h`` and the result is
    ``|(t_enter + (1 - h)) / h|``: exactly ``t_enter`` on a hit, ``+inf`` on a
    miss, whatever the sign of the zero.
    """
    ix = capped_reciprocal(ux)
    iy = capped_reciprocal(uy)
    tx1 = (-hl - ox) * ix
    tx2 = (hl - ox) * ix
    ty1 = (-hw - oy) * iy
    ty2 = (hw - oy) * iy
    # relu(x) is clamp_min(x, 0) to the bit (NaN and -0.0 included), and faster.
    t_enter = torch.relu(
        torch.maximum(torch.minimum(tx1, tx2), torch.minimum(ty1, ty2))
    )
    t_exit = torch.minimum(torch.maximum(tx1, tx2), torch.maximum(ty1, ty2))
    if max_range < math.inf:
        t_exit = t_exit.clamp_max(max_range)
    return hit_or_inf(t_enter, step(t_exit - t_enter))


def capped_reciprocal(x: Tensor) -> Tensor:
    """``1 / x`` clipped to the finite floats: ``x = +-0`` gives ``+-max``.

    Parameters
    ----------
    x : Tensor of shape (...)

    Returns
    -------
    Tensor of shape (...)
        The same values with or without autograd. Under autograd (``x``
        requires a gradient) the zeros are masked before the division, so
        that the backward pass has no ``0 * inf`` (NaN); the gradient is 0
        where ``x`` is 0.
    """
    big = torch.finfo(x.dtype).max
    if x.requires_grad:
        zero = x == 0
        safe = torch.where(zero, 1.0, x)
        capped = torch.clamp(torch.reciprocal(safe), -big, big)
        return torch.where(zero, torch.copysign(torch.full_like(x, big), x), capped)
    return torch.clamp(torch.reciprocal(x), -big, big)


def hit_or_inf(t: Tensor, h: Tensor) -> Tensor:
    """``|t|`` where ``h`` is 1, ``inf`` where it is 0 (a miss), branch-free.

    Parameters
    ----------
    t : Tensor of shape (...)
        Finite or ``inf``.
    h : Tensor of shape (...)
        ``1.0`` or a zero, as :func:`step` gives.

    Returns
    -------
    Tensor of shape (...)
        ``|(t + (1 - h)) / h|``: exactly ``|t|`` on a hit, ``+inf`` on a miss,
        whatever the sign of the zero. Under autograd the same values come
        from a ``where``, whose backward pass has no ``0 * inf`` (NaN) on the
        misses.
    """
    if t.requires_grad:
        return torch.where(h > 0, torch.abs(t), math.inf)
    return torch.abs((t + (1.0 - h)) / h)


def step(x: Tensor) -> Tensor:
    """Heaviside step as arithmetic: ``1.0`` where ``x > 0``, else a zero.

    Parameters
    ----------
    x : Tensor of shape (...)

    Returns
    -------
    Tensor of shape (...)
        Same dtype as ``x``. The zero may be ``-0.0``: divide by it only under
        ``abs`` (compiled code may ignore the sign of zero, so no result here
        depends on it).
    """
    return torch.relu(torch.sign(x))


def min_argmin(d: Tensor, dim: int) -> tuple[Tensor, Tensor]:
    """Smallest entry along ``dim`` and the lowest index where it occurs.

    Written with float arithmetic and two ``amin`` reductions: on CPU,
    ``Tensor.min(dim)`` with indices (and integer reductions) take slow scalar
    paths, and index tracking keeps ``torch.compile`` from fusing the
    reduction with the ray casting that feeds it. The index is the ``amin`` of
    ``j + n * [d_j > min]``, which is exact.

    Parameters
    ----------
    d : Tensor of shape (..., n, ...)
        Not NaN (``inf`` allowed).
    dim : int
        Dimension to reduce.

    Returns
    -------
    values : Tensor of shape (..., ...)
        ``d.amin(dim)``.
    indices : Tensor of int64, shape (..., ...)
        Lowest index of the minimum (0 when every entry is ``inf``).
    """
    n = d.shape[dim]
    values = d.amin(dim=dim)
    big = torch.finfo(d.dtype).max  # inf - inf would be NaN
    above = step(d.clamp_max(big) - values.clamp_max(big).unsqueeze(dim))
    shape = [1] * d.dim()
    shape[dim] = n
    index = torch.arange(n, dtype=d.dtype, device=d.device).reshape(shape)
    return values, (above * n + index).amin(dim=dim).to(torch.int64)


def boxes_overlap(
    xa: Tensor,
    ya: Tensor,
    ca: Tensor,
    sa: Tensor,
    hla: Tensor,
    hwa: Tensor,
    xb: Tensor,
    yb: Tensor,
    cb: Tensor,
    sb: Tensor,
    hlb: Tensor,
    hwb: Tensor,
) -> Tensor:
    """Whether the interiors of two oriented boxes intersect (separating axes).

    Two convex polygons are disjoint iff their projections on some edge normal
    are disjoint; a rectangle pair has four candidate axes. Touching boxes
    (projections meeting at a point) are *not* overlapping.

    Parameters
    ----------
    xa, ya, xb, yb : Tensor of shape (...)
        Box centres [m].
    ca, sa, cb, sb : Tensor of shape (...)
        Cosine and sine of the box headings.
    hla, hwa, hlb, hwb : Tensor of shape (...)
        Half-lengths and half-widths [m].

    Returns
    -------
    Tensor of bool, shape (...)
    """
    dx = xb - xa
    dy = yb - ya
    cos_ab = torch.abs(ca * cb + sa * sb)  # |u_a . u_b| = |v_a . v_b|
    sin_ab = torch.abs(sa * cb - ca * sb)  # |u_a . v_b| = |v_a . u_b|
    d_ua = torch.abs(ca * dx + sa * dy)
    d_va = torch.abs(ca * dy - sa * dx)
    d_ub = torch.abs(cb * dx + sb * dy)
    d_vb = torch.abs(cb * dy - sb * dx)
    return (
        (d_ua < hla + (hlb * cos_ab + hwb * sin_ab))
        & (d_va < hwa + (hlb * sin_ab + hwb * cos_ab))
        & (d_ub < hlb + (hla * cos_ab + hwa * sin_ab))
        & (d_vb < hwb + (hla * sin_ab + hwa * cos_ab))
    )
