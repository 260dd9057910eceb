import math

import pytest
import torch

from avrisk.tensors.mathops import asin, atan, log, sinc, sincos, wrap_angle


def grid(lo, hi, n=20001, dtype=torch.float64):
    return torch.linspace(lo, hi, n, dtype=dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sincos_matches_the_library_to_single_precision(dtype):
    x = grid(-50.0, 50.0, dtype=dtype)
    s, c = sincos(x)
    assert torch.allclose(s.double(), torch.sin(x.double()), atol=3e-7)
    assert torch.allclose(c.double(), torch.cos(x.double()), atol=3e-7)


def test_sincos_is_exact_at_zero_and_keeps_the_pythagorean_identity():
    s, c = sincos(torch.tensor([0.0]))
    assert s.item() == 0.0 and c.item() == 1.0
    s, c = sincos(grid(-10, 10))
    assert torch.allclose(s * s + c * c, torch.ones_like(s), atol=1e-7)


def test_atan_and_asin_match_the_library_including_infinities():
    x = grid(-1e3, 1e3)
    assert torch.allclose(atan(x), torch.atan(x), atol=2e-7)
    assert atan(torch.tensor([math.inf, -math.inf])).tolist() == pytest.approx(
        [math.pi / 2, -math.pi / 2]
    )
    u = grid(-1.0, 1.0)
    assert torch.allclose(asin(u), torch.asin(u), atol=3e-7)
    assert asin(torch.tensor([2.0])).item() == pytest.approx(math.pi / 2)


def test_log_matches_the_library_over_many_decades():
    x = torch.logspace(-30, 30, 5001, dtype=torch.float64)
    assert torch.allclose(log(x), torch.log(x), rtol=0, atol=3e-7 * 70)
    assert log(torch.tensor([1.0])).item() == 0.0


def test_sinc_is_one_at_zero_and_sin_over_x_elsewhere():
    x = grid(-3.0, 3.0, 6001)
    ref = torch.where(x == 0, 1.0, torch.sin(x) / x)
    assert torch.allclose(sinc(x), ref, atol=2e-7)


def test_wrap_angle_maps_every_angle_to_the_half_open_circle():
    x = grid(-20.0, 20.0)
    w = wrap_angle(x)
    assert w.abs().max().item() <= math.pi + 1e-12
    assert torch.allclose(torch.sin(w), torch.sin(x), atol=1e-9)


def test_results_do_not_depend_on_where_an_element_sits_in_the_tensor():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(1000, generator=g) * 5
    for fn in (
        lambda t: sincos(t)[0],
        lambda t: sincos(t)[1],
        atan,
        lambda t: log(t.abs() + 0.1),
    ):
        whole = fn(x)
        single = torch.cat([fn(x[i : i + 1]) for i in range(0, 1000, 37)])
        assert torch.equal(whole[::37], single)
