"""The held-out windows: the shipped test split only, and subsets of them."""

import numpy as np
import pytest

from avrisk.learning.ngsim.loaders import load_i80_pairs
from avrisk.realism.held_out import data_files, held_out_windows, select_windows
from avrisk.sim import Road


def test_the_held_out_windows_come_from_the_shipped_files_whatever_the_environment(
    monkeypatch, tmp_path
):
    monkeypatch.setenv("AVRISK_NGSIM_DIR", str(tmp_path / "nowhere"))
    assert all(p.is_file() for p in data_files().values())
    windows = held_out_windows(150, Road())
    assert windows.n_steps == 150
    pairs = load_i80_pairs(data_files()["i80_pairs"])
    test = pairs.take(pairs.split == "test")
    # The pairs-file windows start with the first test episode's first frame.
    first = np.flatnonzero(test.pair_id == test.pair_id[0])
    np.testing.assert_array_equal(windows.v_f[0], test.v_follower[first[:151]])
    assert windows.has_lateral.any() and not windows.has_lateral.all()


def test_a_subset_is_a_sorted_draw_named_by_held_out_index():
    windows = held_out_windows(100, Road())
    every, labels = select_windows(windows, None, seed=0)
    assert len(every) == len(windows) and labels.tolist() == list(range(len(windows)))
    some, labels = select_windows(windows, 5, seed=3)
    assert len(some) == 5 and len(set(labels.tolist())) == 5
    assert labels.tolist() == sorted(labels.tolist())
    np.testing.assert_array_equal(some.v_f, windows.v_f[labels])
    again, same = select_windows(windows, 5, seed=3)
    assert same.tolist() == labels.tolist()
    assert len(select_windows(windows, 10**6, seed=3)[0]) == len(windows)


def test_each_period_is_held_out_whole_and_the_lateral_file_joins_its_own_only():
    from avrisk.learning.ngsim.loaders import LATERAL_PERIOD
    from avrisk.learning.training.data import training_windows
    from avrisk.realism.held_out import held_out_periods

    road = Road()
    periods = held_out_periods()
    assert periods == ("0400pm-0415pm", "0500pm-0515pm")
    by_period = {p: held_out_windows(150, road, p) for p in periods}
    for p, windows in by_period.items():
        assert windows.has_lateral.any() == (p == LATERAL_PERIOD)
        # a period's windows are its training windows and its test windows
        trained = training_windows(None, 150, (p,))
        assert len(windows) > len(trained) > 0
    # every period, both splits = the training windows and the test windows
    everything = len(training_windows(None, 150)) + len(held_out_windows(150, road))
    assert sum(len(w) for w in by_period.values()) == everything


def test_an_unknown_held_out_set_is_refused():
    with pytest.raises(ValueError, match="0400pm-0415pm"):
        held_out_windows(150, Road(), "0515pm-0530pm")


def test_a_window_whose_vehicles_overlap_lengthwise_is_no_car_following():
    """The 16:00 lateral file has one such window (a leader still in the next lane)."""
    from avrisk.learning.ngsim.lateral import LaneCentres
    from avrisk.learning.ngsim.loaders import lateral_pair_split, load_i80_lateral
    from avrisk.learning.replay import car_following_windows

    road = Road()
    files = data_files()
    pairs = load_i80_pairs(files["i80_pairs"])
    lateral = load_i80_lateral(files["i80_lateral"])
    centres = LaneCentres.fit(
        lateral.take(lateral_pair_split(lateral, pairs) == "train")
    )
    assert (lateral.gap <= 0).any()  # the data have such frames
    windows = car_following_windows(pairs, lateral, centres, 150, road)
    assert len(windows) > 0 and (windows.gap > 0).all()
    for held_out in ("test", "0400pm-0415pm", "0500pm-0515pm"):
        assert (held_out_windows(150, road, held_out).gap > 0).all()


def test_a_periods_test_split_is_its_test_windows_alone():
    from avrisk.realism.held_out import held_out_period, held_out_periods

    road = Road()
    assert held_out_period("test") == (None, True)
    assert held_out_period("0400pm-0415pm") == ("0400pm-0415pm", False)
    assert held_out_period("0400pm-0415pm:test") == ("0400pm-0415pm", True)
    for bad in ("0400pm-0415pm:train", "0515pm-0530pm:test", ":test"):
        with pytest.raises(ValueError, match="0400pm-0415pm"):
            held_out_period(bad)
    test = held_out_windows(150, road)
    parts = [held_out_windows(150, road, f"{p}:test") for p in held_out_periods()]
    assert sum(len(w) for w in parts) == len(test)
    whole = held_out_windows(150, road, "0500pm-0515pm")
    assert 0 < len(parts[1]) < len(whole) and not parts[1].has_lateral.any()
    assert parts[0].has_lateral.any()
    # the period's test windows are among its windows, the same rows
    rows = {w.tobytes() for w in whole.v_f}
    assert all(w.tobytes() in rows for w in parts[1].v_f)
