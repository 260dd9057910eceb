import math

import pytest
import torch

from avrisk.sim.geometry import (
    box_corners,
    boxes_overlap,
    min_argmin,
    ray_box_distance,
    to_local,
)

BATCH_SHAPES = [(), (1,), (7,)]


def full(shape, value, dtype=torch.float32):
    return torch.full(shape, float(value), dtype=dtype)


def ray_to_box(
    shape, origin, direction, centre, heading, length, width, max_range=math.inf
):
    """Cast a world-frame ray at a world-frame box through the box-frame primitive."""
    c, s = math.cos(heading), math.sin(heading)
    lx, ly = to_local(
        full(shape, origin[0]),
        full(shape, origin[1]),
        full(shape, centre[0]),
        full(shape, centre[1]),
        full(shape, c),
        full(shape, s),
    )
    ux = c * direction[0] + s * direction[1]
    uy = c * direction[1] - s * direction[0]
    u = (full(shape, ux), full(shape, uy))
    half = (full(shape, length / 2), full(shape, width / 2))
    return ray_box_distance(lx, ly, *u, *half, max_range)


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_a_ray_hits_an_aligned_box_at_its_near_face(shape):
    d = ray_to_box(shape, (0.0, 0.0), (1.0, 0.0), (10.0, 0.0), 0.0, 4.0, 2.0)
    assert d.shape == shape
    assert torch.all(d == 8.0)


def test_a_ray_hits_a_box_turned_across_it_at_its_long_side():
    d = ray_to_box((), (0.0, 0.0), (1.0, 0.0), (10.0, 0.0), math.pi / 2, 4.0, 2.0)
    assert d.item() == pytest.approx(9.0, abs=1e-6)


def test_a_diagonal_ray_hits_a_diamond_at_its_near_corner():
    # A 2 x 2 box turned 45 degrees has a corner sqrt(2) from its centre.
    direction = (math.sqrt(0.5), math.sqrt(0.5))
    d = ray_to_box((), (0.0, 0.0), direction, (6.0, 6.0), math.pi / 4, 2.0, 2.0)
    assert d.item() == pytest.approx(6.0 * math.sqrt(2) - 1.0, abs=1e-5)


def test_a_ray_at_an_angle_hits_the_face_it_reaches_first():
    # Box [9, 11] x [-1, 1]; ray at 5 degrees from the origin enters through x = 9.
    a = math.radians(5.0)
    d = ray_to_box(
        (), (0.0, 0.0), (math.cos(a), math.sin(a)), (10.0, 0.0), 0.0, 2.0, 2.0
    )
    assert d.item() == pytest.approx(9.0 / math.cos(a), rel=1e-6)


def test_a_ray_that_passes_beside_a_box_misses_it():
    d = ray_to_box((), (0.0, 0.0), (1.0, 0.0), (10.0, 1.5), 0.0, 4.0, 2.0)
    assert d.item() == math.inf


def test_a_ray_pointing_away_from_a_box_misses_it():
    d = ray_to_box((), (0.0, 0.0), (-1.0, 0.0), (10.0, 0.0), 0.0, 4.0, 2.0)
    assert d.item() == math.inf


def test_a_ray_that_only_touches_a_corner_misses():
    # The diagonal y = x touches the box [1, 3] x [-1, 1] only at its corner (1, 1).
    diagonal = (math.sqrt(0.5), math.sqrt(0.5))
    d = ray_to_box((), (0.0, 0.0), diagonal, (2.0, 0.0), 0.0, 2.0, 2.0)
    assert d.item() == math.inf
    # Raised by a hair, the box is entered through its left face.
    d = ray_to_box((), (0.0, 0.0), diagonal, (2.0, 0.01), 0.0, 2.0, 2.0)
    assert d.item() == pytest.approx(math.sqrt(2), rel=1e-6)


def test_a_ray_from_inside_a_box_reads_zero():
    d = ray_to_box((), (10.5, 0.2), (1.0, 0.0), (10.0, 0.0), 0.3, 4.0, 2.0)
    assert d.item() == 0.0


def test_a_hit_beyond_the_range_is_a_miss_and_one_within_it_is_not():
    near = ray_to_box(
        (), (0.0, 0.0), (1.0, 0.0), (10.0, 0.0), 0.0, 4.0, 2.0, max_range=8.5
    )
    far = ray_to_box(
        (), (0.0, 0.0), (1.0, 0.0), (10.0, 0.0), 0.0, 4.0, 2.0, max_range=7.5
    )
    assert near.item() == 8.0
    assert far.item() == math.inf


def test_rays_with_a_zero_direction_component_give_no_nan():
    # Origin exactly on the slab boundary line y = -1 of the box, ray along x.
    d = ray_box_distance(
        torch.tensor([-5.0, -5.0]),
        torch.tensor([-1.0, -2.0]),
        torch.tensor([1.0, 1.0]),
        torch.tensor([0.0, -0.0]),
        torch.tensor([1.0, 1.0]),
        torch.tensor([1.0, 1.0]),
    )
    assert not torch.isnan(d).any()
    assert d[1].item() == math.inf


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_corners_of_an_aligned_box_are_plus_minus_its_half_sizes(shape):
    one = full(shape, 1.0)
    corners = box_corners(0 * one, 0 * one, one, 0 * one, 2 * one, one)
    assert corners.shape == shape + (4, 2)
    expected = torch.tensor([[2.0, 1.0], [-2.0, 1.0], [-2.0, -1.0], [2.0, -1.0]])
    assert torch.equal(corners, expected.expand_as(corners))


def overlap(a, b, dtype=torch.float32, shape=()):
    """a, b: (x, y, heading, length, width)."""

    def args(box):
        x, y, h, length, width = box
        return (
            full(shape, x, dtype),
            full(shape, y, dtype),
            full(shape, math.cos(h), dtype),
            full(shape, math.sin(h), dtype),
            full(shape, length / 2, dtype),
            full(shape, width / 2, dtype),
        )

    return boxes_overlap(*args(a), *args(b))


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_separated_boxes_do_not_overlap(shape):
    res = overlap((0, 0, 0, 4, 2), (10, 0, 0, 4, 2), shape=shape)
    assert res.shape == shape and not res.any()


@pytest.mark.parametrize("shape", BATCH_SHAPES)
def test_overlapping_boxes_overlap(shape):
    res = overlap((0, 0, 0, 4, 2), (3, 1.5, 0.3, 4, 2), shape=shape)
    assert res.shape == shape and res.all()


def test_boxes_touching_only_at_a_corner_do_not_overlap():
    # Corner (2, 1) of the first is corner (2, 1) of the second.
    assert not overlap((0, 0, 0, 4, 2), (4, 2, 0, 4, 2))


def test_boxes_touching_along_an_edge_do_not_overlap():
    assert not overlap((0, 0, 0, 4, 2), (4, 0.5, 0, 4, 2))


def test_boxes_a_hair_closer_than_touching_overlap():
    assert overlap((0, 0, 0, 4, 2), (3.999, 1.999, 0, 4, 2), dtype=torch.float64)


def test_turned_boxes_whose_bounding_boxes_meet_are_separated_by_an_edge_normal():
    # 2 x 2 squares turned 45 degrees, centres d apart along their common
    # diagonal axis: they overlap iff d * sqrt(2) < 2, while their axis-aligned
    # bounding boxes (half-size sqrt(2)) overlap for every d < 2 sqrt(2).
    a = (0.0, 0.0, math.pi / 4, 2.0, 2.0)
    assert not overlap(a, (2.0, 2.0, math.pi / 4, 2.0, 2.0), dtype=torch.float64)
    assert overlap(a, (1.3, 1.3, math.pi / 4, 2.0, 2.0), dtype=torch.float64)


def test_overlap_is_symmetric_and_agrees_with_a_dense_point_test():
    g = torch.Generator().manual_seed(0)
    n = 400
    a = torch.rand(n, 5, generator=g, dtype=torch.float64) * torch.tensor(
        [6, 6, 6.3, 4, 2]
    ) + torch.tensor([0, 0, 0, 1, 0.5])
    b = torch.rand(n, 5, generator=g, dtype=torch.float64) * torch.tensor(
        [6, 6, 6.3, 4, 2]
    ) + torch.tensor([0, 0, 0, 1, 0.5])

    def split(t):
        return (
            t[:, 0],
            t[:, 1],
            torch.cos(t[:, 2]),
            torch.sin(t[:, 2]),
            t[:, 3] / 2,
            t[:, 4] / 2,
        )

    ab = boxes_overlap(*split(a), *split(b))
    ba = boxes_overlap(*split(b), *split(a))
    assert torch.equal(ab, ba)
    # Reference: grid points of one box (interior included) inside the other.
    u = torch.linspace(-0.999, 0.999, 41, dtype=torch.float64)
    gu, gv = torch.meshgrid(u, u, indexing="ij")

    def points_in(p, q):
        x, y, c, s, hl, hw = split(p)
        px = (
            x[:, None]
            + c[:, None] * gu.flatten() * hl[:, None]
            - s[:, None] * gv.flatten() * hw[:, None]
        )
        py = (
            y[:, None]
            + s[:, None] * gu.flatten() * hl[:, None]
            + c[:, None] * gv.flatten() * hw[:, None]
        )
        qx, qy, qc, qs, qhl, qhw = (t[:, None] for t in split(q))
        lx, ly = to_local(px, py, qx, qy, qc, qs)
        return ((lx.abs() < qhl) & (ly.abs() < qhw)).any(dim=1)

    sampled = points_in(a, b) | points_in(b, a)
    # Sampling can only miss thin overlaps: everything it finds SAT must find.
    assert torch.all(ab[sampled])
    assert (ab & ~sampled).sum() <= n // 20


def test_min_argmin_returns_the_exact_minimum_and_the_lowest_index_on_ties():
    d = torch.tensor(
        [[3.0, 1.5, 1.5, math.inf], [math.inf, math.inf, math.inf, math.inf]]
    )
    for dtype in (torch.float32, torch.float64):
        v, i = min_argmin(d.to(dtype), dim=-1)
        assert v.tolist() == [1.5, math.inf]
        assert i.tolist() == [1, 0]


def test_min_argmin_agrees_with_torch_min_on_random_distances():
    g = torch.Generator().manual_seed(1)
    d = torch.rand(50, 5, 30, generator=g) * 100
    d[d > 80] = math.inf
    v, i = min_argmin(d, dim=-2)
    ref_v, ref_i = d.min(dim=-2)
    assert torch.equal(v, ref_v)
    finite = torch.isfinite(ref_v)
    assert torch.equal(i[finite], ref_i[finite])
