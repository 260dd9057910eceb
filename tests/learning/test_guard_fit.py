"""The brake fitted to human closing-in: its quantiles, and its counts."""

import numpy as np
import pytest
import torch

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.learning.guard_fit import engagements, fit_brake_guard, guard_conditions
from tests.learning.recorded_windows import recorded_windows

T = 99


def closing_windows(rng, n=40):
    """Followers closing in at 0-3 m/s on leaders at 10 m/s, gaps 1-30 m."""
    closing = rng.uniform(-1.0, 3.0, size=(n, T + 1))
    gap = rng.uniform(1.0, 30.0, size=(n, T + 1))
    v_l = np.full((n, T + 1), 10.0)
    return recorded_windows(v_f=list(v_l + closing), v_l=list(v_l), gap=list(gap))


def test_the_fit_is_the_stated_quantiles_of_the_humans_closing_steps():
    windows = closing_windows(np.random.default_rng(0))
    fit = fit_brake_guard(windows, gap_quantile=0.05, decel_quantile=0.99)
    closing = windows.v_f - windows.v_l
    steps = closing > 0
    floor = np.quantile(windows.gap[steps], 0.05)
    assert fit.guard.gap_floor == pytest.approx(floor)
    assert fit.guard.hold_floor and fit.closing_steps == steps.sum()
    needed = closing[steps] ** 2 / (2 * np.maximum(windows.gap[steps] - floor, 0.1))
    assert fit.guard.engage_decel == pytest.approx(np.quantile(needed, 0.99))
    # the brake would act in the closing steps beyond either quantile, no more
    acting = guard_conditions(fit.guard, windows.gap, windows.v_f, windows.v_l)
    inside = steps & (windows.gap < floor)
    beyond = steps & (needed_all(windows, floor) > fit.guard.engage_decel)
    np.testing.assert_array_equal(acting, inside | beyond)
    assert fit.human_share == pytest.approx(acting.mean())


def needed_all(windows, floor):
    closing = np.maximum(windows.v_f - windows.v_l, 0.0)
    return closing**2 / (2 * np.maximum(windows.gap - floor, 0.1))


def test_the_conditions_are_the_brakes_own_where_the_leader_is_on_the_beam():
    rng = np.random.default_rng(1)
    gap = rng.uniform(0.0, 10.0, (5, 7))
    v_f, v_l = rng.uniform(0, 10, (5, 7)), rng.uniform(0, 10, (5, 7))
    guard = BrakeGuard(2.0, 1.5, hold_floor=True)
    length = torch.full((5, 7), 4.0, dtype=torch.float64)
    free = torch.full((5, 7), np.inf, dtype=torch.float64)
    limited = guard.limit(
        free,
        torch.as_tensor(gap) + 2.0,
        torch.as_tensor(v_l - v_f),
        torch.zeros((5, 7), dtype=torch.int64),
        length,
    )
    acting = guard_conditions(guard, gap, v_f, v_l)
    np.testing.assert_array_equal(acting, torch.isfinite(limited).numpy())


def test_an_engagement_is_counted_once_however_long_and_not_after_a_crash():
    acting = np.array([[1, 1, 0, 1, 1, 1], [0, 0, 1, 1, 0, 1]], bool)
    alive = np.array([[1, 1, 1, 1, 1, 1], [1, 1, 1, 1, 0, 0]], bool)
    assert engagements(acting, alive) == 2 + 1


def test_quantiles_outside_the_unit_interval_are_refused():
    windows = closing_windows(np.random.default_rng(2), n=2)
    with pytest.raises(ValueError, match="quantiles"):
        fit_brake_guard(windows, gap_quantile=0.0)
