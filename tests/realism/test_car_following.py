"""Part A's samples, summary and targets on hand-built replays with known answers."""

import dataclasses

import numpy as np
import pytest

from avrisk.realism.car_following import (
    IMPACT_COLUMNS,
    PartA,
    followers,
    recorded,
    summarise_part_a,
)
from avrisk.realism.tables import collision_table, part_a_table, targets_table
from avrisk.realism.targets import part_a_targets
from avrisk.sim import Road
from tests.learning.recorded_windows import recorded_windows

T = 10  # steps per window


def two_windows():
    """Two 1 s windows: steady following at 10 m/s, and a leader braking to 0."""
    v_l_stop = np.linspace(5.0, 0.0, T + 1)
    return recorded_windows(
        v_f=[np.full(T + 1, 10.0), np.full(T + 1, 5.0)],
        v_l=[np.full(T + 1, 10.0), v_l_stop],
        gap=[np.full(T + 1, 20.0), np.linspace(6.0, 3.5, T + 1)],
    )


def crash_in_second_window(windows):
    """The record, except that the second follower hits its leader at step 6."""
    r = recorded(windows)
    alive = r.alive.copy()
    alive[1, 7:] = False
    v = r.v.copy()
    v[1, :7] = [5.0, 5.0, 4.8, 4.6, 4.4, 4.4, 4.4]  # -2 m/s^2 at its hardest
    gap = r.gap.copy()
    gap[1, -1] = 0.0
    return dataclasses.replace(
        r, v=v, gap=gap, alive=alive, crash=np.array([False, True])
    )


def test_road_departures_are_measured_alike_on_the_record_and_in_replays():
    # A follower recorded with a side over the right edge (lane 0's centre
    # is 1.85 m from it; half width 1.15 m): the record and a replay that
    # stays there have no departure; a replay that drives on the road, then
    # over the edge, has one.
    windows = two_windows()
    windows = dataclasses.replace(
        windows,
        lane=np.zeros(2, np.int64),
        width_f=np.full(2, 2.3),
        offset=np.full((2, T + 1), -0.9),
    )
    road = Road()
    assert (
        followers(windows, recorded(windows), road, np.arange(2)).road_departures == 0
    )
    leaves = recorded(windows)
    offset = np.zeros((2, T + 1))
    offset[1, 5:] = -0.9
    leaves = dataclasses.replace(leaves, offset=offset)
    assert followers(windows, leaves, road, np.arange(2)).road_departures == 1


def test_the_record_has_no_collision_and_no_gap_error():
    windows = two_windows()
    human = followers(windows, recorded(windows), Road(), np.arange(2))
    assert human.collisions == 0 and human.road_departures == 0
    assert human.gap_rmse == 0.0 and human.impacts.shape == (0, 7)
    assert human.hours == pytest.approx(2 * T * 0.1 / 3600)
    assert human.samples["speed"].size == 2 * (T + 1)
    assert human.samples["offset"].size == 0  # no lateral-file window
    # TTC only where closing: the second window, gap / (5 - v_leader).
    closing = 5.0 - windows.v_l[1] > 0.05
    expected = np.minimum(windows.gap[1][closing] / (5.0 - windows.v_l[1][closing]), 20)
    np.testing.assert_allclose(human.samples["ttc"], expected)


def test_a_collision_is_counted_once_with_its_window_speed_and_braking():
    windows = two_windows()
    sim = followers(windows, crash_in_second_window(windows), Road(), np.array([7, 40]))
    assert sim.collisions == 1
    assert sim.impacts.shape == (1, len(IMPACT_COLUMNS))
    window, step, speed, leader, decel, human_decel, near_stop = sim.impacts[0]
    assert (window, step, speed) == (40, 6, 4.4)
    assert leader == pytest.approx(windows.v_l[1, 6])
    assert decel == pytest.approx(-2.0) and human_decel == pytest.approx(0.0)
    assert near_stop == 1.0  # the leader comes to 0 m/s in the window
    np.testing.assert_array_equal(sim.collisions_by_window, [0, 1])
    assert sim.samples["speed"].size == 2 * (T + 1) - 4  # frames 7-10 are dead
    assert sim.gap_rmse == pytest.approx(np.sqrt(3.5**2 / 2))


def part(windows, **models):
    labels = np.arange(len(windows))
    road = Road()
    return PartA(
        windows=windows,
        labels=labels,
        replicates=1,
        human=followers(windows, recorded(windows), road, labels),
        models={k: followers(windows, r, road, labels) for k, r in models.items()},
        replays=models,
    )


def test_a_model_that_drives_as_the_humans_did_is_at_distance_zero_and_passes():
    windows = two_windows()
    crashing = crash_in_second_window(windows)
    summary = summarise_part_a(
        part(windows, twin=recorded(windows), crashing=crashing, IDM=crashing)
    )
    twin, crash = summary["models"]["twin"], summary["models"]["crashing"]
    for key in ("speed", "accel", "jerk", "gap", "ttc"):
        assert twin[key]["ks"] == 0.0 and twin[key]["w1"] == 0.0
        assert twin[key]["p5"] == summary["human"][key]["p5"]
    assert twin["offset"] is None  # no sample on either side
    assert crash["collisions"]["count"] == 1
    assert crash["collisions"]["per_hour"] == pytest.approx(1 / (2 * T * 0.1 / 3600))
    targets = part_a_targets(summary)
    assert list(targets) == ["twin", "crashing"]  # IDM is the reference
    passed = {t.target: t.passed for t in targets["twin"]}
    assert all(passed.values()), passed
    by_name = {t.target: t for t in targets["crashing"]}
    assert not by_name["collisions <= 0.5 /veh-h"].passed
    # As close as IDM (its twin) everywhere: never closer, except where both
    # match the humans exactly (zero hard brakes, zero road departures).
    assert by_name["closer to humans than IDM (8 of the 9 metrics)"].figure == "2 of 8"


def test_the_tables_show_every_model_and_the_collisions_window():
    windows = two_windows()
    crashing = crash_in_second_window(windows)
    summary = summarise_part_a(part(windows, learned=crashing, IDM=recorded(windows)))
    table = part_a_table(summary)
    assert "| metric | human (held out) | learned | IDM |" in table
    assert "| lateral offset (lateral-file windows): KS / W1 | - | n/a | n/a |" in table
    assert "(1) |" in table  # one collision of the learned model
    assert "(1 of 2) |" in table  # in one of the two windows
    assert "| learned | 1 | 1 (1: 1) | 4.4 |" in collision_table(summary)
    assert "| IDM | 0 | - |" in collision_table(summary)
    targets = targets_table(part_a_targets(summary))
    assert targets.count("\n") == 3 + 8  # title, blank, header, rule; 8 targets
    assert "| collisions <= 0.5 /veh-h | 1800.00 FAIL |" in targets


def test_collisions_are_summed_per_window_over_its_replays():
    windows = two_windows()
    crashing = crash_in_second_window(windows)
    # Three replays of window 40 (two crash) and one of window 7, interleaved
    # as run_part_a tiles them.
    take = np.array([1, 0, 1, 1])
    replays = dataclasses.replace(
        crashing,
        **{
            k: getattr(crashing, k)[take]
            for k in ("v", "v_l", "gap", "offset", "alive", "crash", "offroad")
        },
    )
    replays.crash[2] = False
    sim = followers(windows.take(take), replays, Road(), np.array([40, 7, 40, 40]))
    np.testing.assert_array_equal(sim.collisions_by_window, [2, 0])


def test_speed_bands_split_the_same_replays_and_margins_agree_with_verdicts():
    from avrisk.realism.periods import band_summaries, window_bands

    windows = two_windows()  # leaders at 10 m/s and braking from 5 to 0 m/s
    assert window_bands(windows).tolist() == ["flowing", "congested"]
    crashing = crash_in_second_window(windows)
    whole = part(windows, learned=crashing, IDM=recorded(windows))
    bands = band_summaries(whole, Road())
    assert set(bands) == {"flowing", "congested"}
    congested = bands["congested"]["summary"]
    assert congested["windows"] == 1
    assert congested["models"]["learned"]["collisions"]["count"] == 1
    assert bands["flowing"]["summary"]["models"]["learned"]["collisions"]["count"] == 0
    assert (
        congested["human"]["speed"]
        == summarise_part_a(
            part(windows.take([1]), learned=crashing.take([1]), IDM=crashing.take([1]))
        )["human"]["speed"]
    )
    for band in bands.values():
        for t in band["targets"]["learned"]:
            assert t["margin"] is None or (t["margin"] >= 0) == t["passed"]
