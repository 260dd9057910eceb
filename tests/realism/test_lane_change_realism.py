"""Part B's measures on a hand-built trace, and its summary and table."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from avrisk.learning.ngsim.us101_lane_changes import (
    load_lane_change_tables,
    split_statistics,
)
from avrisk.realism.lane_changes import (
    RATE_TOLERANCE,
    collision_onsets,
    measure,
    summarise_lane_changes,
)
from avrisk.realism.tables import lane_change_table
from avrisk.sim import VehicleState

W = 3.7  # lane width [m]
FRAMES = 100  # 9.9 s


def trace(change: bool):
    """One scene: vehicle 0 at 10 m/s runs into vehicle 1, stopped in lane 1.

    Vehicle 0 starts in lane 0 and, with ``change``, moves to lane 1 around
    t = 3 s, reaching the stopped vehicle's bumper at t = 3.95 s (frame 40).
    """
    t = np.arange(FRAMES) * 0.1
    y0 = 0.5 * W + (W / (1 + np.exp(-(t - 3.0) / 0.5)) if change else 0 * t)
    x = np.stack([10.0 * t, np.full(FRAMES, 44.0)], -1)[None]  # (1, T+1, 2)
    y = np.stack([y0, np.full(FRAMES, 1.5 * W)], -1)[None]
    as_tensor = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    return SimpleNamespace(
        x=as_tensor(x),
        y=as_tensor(y),
        heading=torch.zeros(1, FRAMES, 2),
        speed=as_tensor(np.stack([np.full(FRAMES, 10.0), np.zeros(FRAMES)], -1)[None]),
        alive=torch.ones(1, FRAMES, dtype=torch.bool),
    )


def sizes():
    one = torch.ones(1, 2)
    return VehicleState(0 * one, 0 * one, 0 * one, 0 * one, 4.5 * one, 1.9 * one)


def test_a_collision_during_a_lane_change_is_one_onset_of_that_pair():
    onsets = collision_onsets(trace(change=True), sizes())
    assert onsets.tolist() == [[0, 0, 1, 40]]
    m = measure(trace(change=True), sizes(), W, noise=0.2)
    assert len(m.changes) == 1 and m.changes.direction.tolist() == [1]
    assert m.changes.track.tolist() == [0]  # scene 0, vehicle 0
    assert (m.collisions, m.lc_collisions, m.vehicles) == (1, 1, 2)
    assert m.hours == pytest.approx(2 * (9.9 - 2.0) / 3600)
    assert m.driven_hours == pytest.approx(2 * 9.9 / 3600)


def test_no_change_and_no_collision_when_the_vehicle_keeps_its_lane():
    m = measure(trace(change=False), sizes(), W, noise=0.2)
    assert (len(m.changes), m.collisions, m.lc_collisions) == (0, 0, 0)
    assert collision_onsets(trace(change=False), sizes()).shape == (0, 4)


def test_the_summary_and_table_judge_the_rate_against_the_held_out_humans():
    tables = load_lane_change_tables()
    held_out, train = (
        split_statistics(tables, "test"),
        split_statistics(tables, "train"),
    )
    results = {
        "changer": measure(trace(change=True), sizes(), W, noise=0.2),
        "keeper": measure(trace(change=False), sizes(), W, noise=0.2),
    }
    summary = summarise_lane_changes(results, held_out, train)
    changer, keeper = summary["models"]["changer"], summary["models"]["keeper"]
    rate = 1 / results["changer"].hours
    assert changer["rate"] == pytest.approx(rate)
    assert changer["vs_held_out"] == pytest.approx(rate / held_out.rate - 1)
    assert changer["target_met"] == (abs(rate / held_out.rate - 1) <= RATE_TOLERANCE)
    assert changer["lc_collisions"]["count"] == 1
    assert keeper["rate"] == 0.0 and keeper["duration_q50"] is None
    assert not keeper["target_met"]
    assert summary["human_held_out"]["changes"] == held_out.changes
    table = lane_change_table(summary, scenes=1, horizon=10.0, seed=3)
    assert "(1 random six-lane scenes x 6 vehicles x 10 s, seed 3;" in table
    assert "| keeper | 0.0 [0.0, " in table and "| -100% FAIL | - | - |" in table
    assert len(table.splitlines()) == 2 + 2 + 3  # title, blank; header, rule; 3 rows
