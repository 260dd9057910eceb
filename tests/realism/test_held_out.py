"""The held-out windows: the shipped test split only, and subsets of them."""

import numpy as np

from avrisk.learning.ngsim import load_i80_pairs
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
