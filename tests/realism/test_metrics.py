"""The realism report's measures on hand-built trajectories with known answers."""

import numpy as np
import pytest
from scipy import stats

from avrisk.realism.metrics import (
    TTC_CAP,
    clustered_event_rate,
    event_rate,
    hard_brake_events,
    kinematics,
    ks_w1,
    lane_index_changes,
    percentiles,
    relative_gap,
    road_departures,
    stopped_fraction,
    ttc_samples,
)


def test_identical_samples_are_at_distance_zero_and_a_shift_moves_w1_by_it(rng):
    x = rng.normal(size=500)
    assert ks_w1(x, x.copy()) == (0.0, 0.0)
    ks, w1 = ks_w1(x, x + 3.0)
    assert w1 == pytest.approx(3.0)
    assert ks == pytest.approx(stats.ks_2samp(x, x + 3.0).statistic)
    assert ks_w1(x, np.zeros(0)) is None


def test_kinematics_of_a_constant_deceleration_with_a_dead_tail():
    v = np.array([[20.0, 19.8, 19.6, 19.4, 19.2, 19.0]])  # -2 m/s^2
    alive = np.array([[True, True, True, True, False, False]])
    k = kinematics(v, alive)
    assert k.speed.tolist() == [20.0, 19.8, 19.6, 19.4]
    np.testing.assert_allclose(k.accel, [-2.0, -2.0, -2.0])  # 3 alive differences
    np.testing.assert_allclose(k.jerk, [0.0, 0.0], atol=1e-9)
    assert k.accel_all.shape == (1, 5)
    assert k.accel_ok.tolist() == [[True, True, True, False, False]]


def test_hard_braking_counts_episodes_not_frames():
    accel = np.array(
        [
            [-4.0, -4.0, 0.0, -5.0, -5.0, -5.0, 0.0],  # under way at frame 0, then one
            [0.0, -2.9, -3.0, 0.0, 0.0, -3.1, 0.0],  # -3.0 is not below -3: one
        ]
    )
    ok = np.ones_like(accel, bool)
    assert hard_brake_events(accel, ok) == 3
    ok[0, 3:] = False  # the second episode of vehicle 0 is not alive
    assert hard_brake_events(accel, ok) == 2


def test_ttc_is_gap_over_closing_speed_capped_and_only_when_closing():
    gap = np.array([[10.0, 10.0, 10.0, 100.0]])
    v = np.array([[12.0, 10.0, 9.0, 11.0]])
    v_l = np.array([[10.0, 10.0, 10.0, 10.0]])  # closing at 2, 0, -1, 1 m/s
    alive = np.ones_like(gap, bool)
    assert ttc_samples(gap, v, v_l, alive).tolist() == [5.0, TTC_CAP]
    alive[0, 0] = False
    assert ttc_samples(gap, v, v_l, alive).tolist() == [TTC_CAP]


def test_lane_index_changes_need_the_margin_beyond_the_marking():
    wobble = [0.5, 0.95, 1.2, 0.9, 0.5]  # over the marking by 0.2 < 0.3: none
    over_and_back = [0.5, 1.5, 1.5, 0.5]  # two changes
    two_lanes = [0.5, 1.4, 2.4, 2.5]  # lane 0 -> 1 -> 2
    pos = np.array([wobble[:4], over_and_back, two_lanes])
    alive = np.ones_like(pos, bool)
    assert lane_index_changes(pos[:1], alive[:1]) == 0
    assert lane_index_changes(pos[1:2], alive[1:2]) == 2
    assert lane_index_changes(pos[2:], alive[2:]) == 2
    alive[1, 2:] = False  # the way back is after the end of the replay
    assert lane_index_changes(pos[1:2], alive[1:2]) == 1


@pytest.mark.parametrize("k, hours", [(0, 2.0), (1, 0.5), (7, 3.0), (40, 20.2)])
def test_the_rate_interval_is_the_exact_poisson_one(k, hours):
    rate = event_rate(k, hours)
    low, high = rate["ci95"]
    assert rate["count"] == k and rate["per_hour"] == pytest.approx(k / hours)
    # Garwood: the mean at each end leaves 2.5% on the far side of k.
    assert stats.poisson.cdf(k, high * hours) == pytest.approx(0.025)
    if k == 0:
        assert low == 0.0
    else:
        assert stats.poisson.sf(k - 1, low * hours) == pytest.approx(0.025)


def test_percentiles_stopped_share_and_relative_gap():
    x = np.arange(101.0)
    assert percentiles(x) == {"p5": 5.0, "p10": 10.0, "p50": 50.0, "p95": 95.0}
    assert percentiles(np.zeros(0)) is None
    assert stopped_fraction(np.array([0.0, 0.05, 3.0, 10.0])) == 0.5
    assert np.isnan(stopped_fraction(np.zeros(0)))
    assert relative_gap(-0.85, -1.0) == pytest.approx(0.15)
    assert relative_gap(0.0, 0.0) == 0.0
    assert relative_gap(0.1, 0.0) == np.inf


def test_a_road_departure_is_an_onset_over_either_edge_while_alive():
    hw = np.array([1.0, 1.0, 1.0, 1.0])
    y = np.array(
        [
            [5.0, 5.0, 9.5, 9.5],  # over the left edge (10 m road): one
            [5.0, 0.5, 5.0, 0.5],  # leaves twice: still one vehicle
            [0.5, 0.5, 5.0, 5.0],  # starts over the edge, comes back: none
            [5.0, 5.0, 0.5, 0.5],  # leaves after its last alive frame: none
        ]
    )
    alive = np.ones_like(y, bool)
    alive[3, 2:] = False
    assert road_departures(y, hw, 10.0, alive) == 2


def test_without_clustering_the_window_interval_is_the_poisson_one():
    spread = clustered_event_rate(np.array([1] * 12 + [0] * 88), 10.0)
    assert spread["dispersion"] == 1.0 and spread["windows_with_events"] == 12
    assert spread["ci95_windows"] == spread["ci95"] == event_rate(12, 10.0)["ci95"]
    none = clustered_event_rate(np.zeros(5, int), 1.0)
    assert none["ci95_windows"] == none["ci95"] and none["count"] == 0
    with pytest.raises(ValueError, match="counts"):
        clustered_event_rate(np.array([-1, 2]), 1.0)


@pytest.mark.parametrize(
    ("share", "p_prone", "p_base", "least_windows", "most_poisson"),
    [
        (0.0, 0.0, 0.002, 0.92, 1.0),  # independent replays: both cover
        (0.02, 0.3, 0.0005, 0.90, 0.75),  # a few crash-prone windows
    ],
)
def test_coverage_of_the_window_interval_when_collisions_cluster(
    share, p_prone, p_base, least_windows, most_poisson
):
    """300 simulated reports of 202 windows x 24 replays (the full sweep:
    benchmarks/collision_interval_coverage.py). A coverage of 0.95 over 300
    reports has a standard error of 0.013."""
    rng = np.random.default_rng(3)
    windows, replicates, hours = 202, 24, 202 * 24 * 15 / 3600
    truth = (share * p_prone + (1 - share) * p_base) * replicates * windows / hours
    covered = {"ci95": 0, "ci95_windows": 0}
    for _ in range(300):
        prone = rng.random(windows) < share
        counts = rng.binomial(replicates, np.where(prone, p_prone, p_base))
        rate = clustered_event_rate(counts, hours)
        for key in covered:
            covered[key] += rate[key][0] <= truth <= rate[key][1]
    assert covered["ci95_windows"] / 300 >= least_windows
    assert covered["ci95"] / 300 <= most_poisson
