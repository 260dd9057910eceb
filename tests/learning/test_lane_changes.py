import dataclasses

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest

from avrisk.learning.ngsim.files import US101_FILE
from avrisk.learning.ngsim.lane_changes import (
    LaneChanges,
    detect_in_episodes,
    detect_lane_changes,
    exposure_seconds,
    poisson_rate_interval,
)
from avrisk.learning.ngsim.loaders import load_us101
from avrisk.learning.ngsim.us101_lane_changes import (
    HELD_OUT_FRACTION,
    lane_change_tables,
    load_lane_change_tables,
    split_statistics,
    us101_split,
)
from tests.ngsim_originals import original_file

DT = 0.1
W = 3.6
T = np.arange(0.0, 40.0, DT)


def logistic_change(t_cross, tau, lanes=1, start_lane=0):
    """Centre of ``start_lane`` to ``lanes`` lanes over, crossing at ``t_cross``."""
    y0 = (start_lane + 0.5) * W
    return y0 + lanes * W / (1.0 + np.exp(-(T - t_cross) / tau))


def test_one_smooth_change_is_found_with_its_crossing_duration_and_peak():
    tau, noise = 0.8, 0.2
    ev = detect_lane_changes(
        logistic_change(15.0, tau), DT, lane_width=W, noise_speed=noise, smoothing=0
    )
    assert len(ev) == 1 and ev.direction.tolist() == [1]
    assert ev.crossing_time[0] == pytest.approx(15.0, abs=DT)
    # Exact logistic: peak W / (4 tau); above v0 while e/(1+e)^2 > v0 tau / W.
    assert ev.peak_lateral_speed[0] == pytest.approx(W / (4 * tau), rel=1e-2)
    q = noise * tau / W
    e_plus = ((1 - 2 * q) + np.sqrt(1 - 4 * q)) / (2 * q)
    assert ev.duration[0] == pytest.approx(2 * tau * np.log(e_plus), abs=2 * DT)


def test_noise_excursions_and_unconfirmed_crossings_are_not_changes():
    rng = np.random.default_rng(0)
    keep = 1.5 * W + rng.normal(0.0, 0.1, T.size)  # lane 1, jittering
    assert len(detect_lane_changes(keep, DT, lane_width=W, noise_speed=0.2)) == 0
    # Over the marking for 1 s and back: not settled in the new lane.
    excursion = np.where((T > 10) & (T < 11), 2.1 * W, 1.5 * W)
    assert len(detect_lane_changes(excursion, DT, lane_width=W, noise_speed=0.2)) == 0
    # Crossing 1 s before the end: cannot be confirmed (exposure stops 2 s early).
    late = logistic_change(T[-1] - 1.0, 0.5)
    assert len(detect_lane_changes(late, DT, lane_width=W, noise_speed=0.2)) == 0
    assert exposure_seconds(T.size, DT) == pytest.approx((T.size - 1) * DT - 2.0)


def test_a_double_change_counts_twice_and_right_is_negative():
    y = logistic_change(20.0, 1.5, lanes=-2, start_lane=3)
    ev = detect_lane_changes(y, DT, lane_width=W, noise_speed=0.2)
    assert ev.direction.tolist() == [-1, -1]
    assert ev.crossing[0] < ev.crossing[1]


def test_episodes_are_detected_separately_with_their_index():
    y = np.concatenate([logistic_change(10.0, 0.8), 1.5 * W + 0 * T])
    starts, ends = np.array([0, T.size]), np.array([T.size, 2 * T.size])
    ev = detect_in_episodes(y, starts, ends, DT, lane_width=W, noise_speed=0.2)
    assert ev.track.tolist() == [0]
    assert len(LaneChanges.concat([])) == 0


def test_poisson_interval_matches_the_chi_square_tables():
    assert poisson_rate_interval(0, 2.0)[1] == pytest.approx(3.6889 / 2, rel=1e-4)
    low, high = poisson_rate_interval(10, 1.0)
    assert (low, high) == pytest.approx((4.7954, 18.3904), rel=1e-4)
    with pytest.raises(ValueError, match="exposure > 0"):
        poisson_rate_interval(1, 0.0)


def test_the_split_holds_out_a_third_by_vehicle_id_only():
    ids = np.arange(1000, 1370)
    split = us101_split(ids)
    assert (split == "test").sum() == round(370 * HELD_OUT_FRACTION)
    # Order and repeats of the ids do not matter; another seed, another draw.
    assert np.array_equal(us101_split(np.r_[ids[::-1], ids[:5]]), split)
    assert not np.array_equal(us101_split(ids, seed=1), split)


def test_the_shipped_tables_agree_with_each_other_and_the_split():
    tables = load_lane_change_tables()
    veh, ev = tables.vehicles, tables.events
    ids = veh["vehicle_id"].to_numpy()
    assert np.array_equal(veh["split"].to_numpy().astype(str), us101_split(ids))
    counts = {int(i): 0 for i in ids}
    for i in ev["vehicle_id"].to_numpy():
        counts[int(i)] += 1
    assert list(counts.values()) == veh["lane_changes"].to_pylist()
    train = split_statistics(tables, "train")
    test = split_statistics(tables, "test")
    assert train.changes + test.changes == ev.num_rows
    held = pc.sum(pc.equal(veh["split"], "test")).as_py()
    assert test.vehicles == held and train.vehicles == veh.num_rows - held
    assert test.rate_low < test.rate < test.rate_high


def test_the_shipped_tables_are_reproduced_from_the_original_file():
    tables = lane_change_tables(load_us101(original_file(US101_FILE)))
    assert tables.equals(load_lane_change_tables())


def test_tables_agree_to_rounding_only():
    shipped = load_lane_change_tables()
    ev = shipped.events
    speed = ev["peak_lateral_speed"].to_numpy()

    def with_speed(values):
        column = ev.schema.get_field_index("peak_lateral_speed")
        events = ev.set_column(column, "peak_lateral_speed", pa.array(values))
        return dataclasses.replace(shipped, events=events)

    assert shipped.equals(with_speed(speed * (1 + 1e-14)))  # rounding
    assert not shipped.equals(with_speed(speed * (1 + 1e-9)))
    noisier = dataclasses.replace(shipped, noise_speed=shipped.noise_speed * 1.001)
    assert not shipped.equals(noisier)
    fewer = dataclasses.replace(shipped, events=ev.slice(1))
    assert not shipped.equals(fewer)
