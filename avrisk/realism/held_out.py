"""The held-out human data of the realism report, chosen before any training.

* Part A: the NGSIM I-80 car-following episodes of the ``test`` split (the
  ``split`` column of the pairs file, and
  :func:`~avrisk.learning.ngsim.loaders.lateral_pair_split` for the lateral
  file; training never reads them), cut
  into non-overlapping windows (:func:`held_out_windows`);
* Part B: the third of the US-101 vehicles held out at random with seed 21
  (:func:`~avrisk.learning.ngsim.us101_lane_changes.us101_split`), as two small
  lane-change tables.

Part A's windows can instead be those of one recording period
(:func:`held_out_windows` with ``held_out`` a period name, both splits): for
leave-one-period-out validation, drivers trained on the other period only
(``avrisk train-drivers --period``) are scored on all of it. The lateral file
covers 16:00-16:15 only, so its windows join that period's set alone.

Only the files shipped in the package (``avrisk/data/ngsim/``,
:func:`data_files`) are read, whatever ``$AVRISK_NGSIM_DIR`` says.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from avrisk.learning.ngsim.files import (
    I80_LATERAL,
    I80_PAIRS,
    default_ngsim_dir,
    ngsim_file,
)
from avrisk.learning.ngsim.lateral import LaneCentres
from avrisk.learning.ngsim.loaders import (
    LATERAL_PERIOD,
    lateral_pair_split,
    load_i80_lateral,
    load_i80_pairs,
    periods_of,
)
from avrisk.learning.ngsim.us101_lane_changes import EVENTS_FILE, VEHICLES_FILE
from avrisk.learning.replay import CarFollowingWindows, car_following_windows
from avrisk.sim import Road

__all__ = [
    "HELD_OUT_TEST",
    "data_files",
    "held_out_period",
    "held_out_periods",
    "held_out_windows",
    "select_windows",
]

#: ``held_out`` of the test splits of every period (the default report).
HELD_OUT_TEST = "test"


def data_files() -> dict[str, Path]:
    """The shipped files the report reads, by role.

    Returns
    -------
    dict of str to Path
        ``i80_pairs``, ``i80_lateral`` (part A), ``us101_vehicles``,
        ``us101_lane_changes`` (part B).
    """
    folder = default_ngsim_dir()
    return {
        "i80_pairs": ngsim_file(I80_PAIRS, folder),
        "i80_lateral": ngsim_file(I80_LATERAL, folder),
        "us101_vehicles": folder / VEHICLES_FILE,
        "us101_lane_changes": folder / EVENTS_FILE,
    }


def held_out_periods() -> tuple[str, ...]:
    """The I-80 recording periods shipped, sorted (e.g. ``"0400pm-0415pm"``)."""
    return periods_of(load_i80_pairs(data_files()["i80_pairs"]))


def held_out_period(
    held_out: str, periods: tuple[str, ...] | None = None
) -> tuple[str | None, bool]:
    """The period a held-out set is drawn from, and whether from its test split only.

    ``(None, True)`` for :data:`HELD_OUT_TEST` (every period's test split);
    ``(period, False)`` for a period's name; ``(period, True)`` for
    ``"{period}:test"``. A ValueError naming the valid sets otherwise.
    ``periods`` are the periods shipped (:func:`held_out_periods`, read
    from the pairs file when None).
    """
    if held_out == HELD_OUT_TEST:
        return None, True
    periods = held_out_periods() if periods is None else periods
    period, _, split = held_out.partition(":")
    if period in periods and split in ("", HELD_OUT_TEST):
        return period, bool(split)
    raise ValueError(
        f"held-out set {held_out!r}: not {HELD_OUT_TEST!r}, one of the periods "
        f"{', '.join(periods)}, nor a period then ':{HELD_OUT_TEST}'"
    )


def held_out_windows(
    n_steps: int, road: Road, held_out: str = HELD_OUT_TEST
) -> CarFollowingWindows:
    """Windows of ``n_steps`` of a held-out set (lane centres: training split).

    Parameters
    ----------
    n_steps : int
        ``T``, steps of :data:`~avrisk.realism.metrics.DT` per window (150 for
        15 s).
    road : Road
        The road the windows are replayed on (lanes mapped onto it).
    held_out : str, default=HELD_OUT_TEST
        :data:`HELD_OUT_TEST`: the test splits of every period; a period
        name (:func:`held_out_periods`): every pair of that period, both
        splits, with the lateral file's pairs if it is 16:00-16:15; a period
        name then ``":test"`` (e.g. ``"0400pm-0415pm:test"``): that period's
        test split only, the validation set of drivers trained on its
        training split alone (a recipe is chosen there, before it is
        scored on the period it never saw).

    Returns
    -------
    CarFollowingWindows
        ``W`` windows, those of the pairs file first (202 of 150 steps for
        the test splits).

    Raises
    ------
    ValueError
        For a ``held_out`` that is neither.
    """
    files = data_files()
    pairs = load_i80_pairs(files["i80_pairs"])
    lat = load_i80_lateral(files["i80_lateral"])
    split = lateral_pair_split(lat, pairs)
    centres = LaneCentres.fit(lat.take(split == "train"))
    period, test_only = held_out_period(held_out, periods_of(pairs))
    keep_pairs = np.full(len(pairs), True) if period is None else pairs.period == period
    keep_lat = np.full(len(lat), period in (None, LATERAL_PERIOD))
    if test_only:
        keep_pairs &= pairs.split == "test"
        keep_lat &= split == "test"
    return car_following_windows(
        pairs.take(keep_pairs), lat.take(keep_lat), centres, n_steps, road
    )


def select_windows(
    windows: CarFollowingWindows, n: int | None, seed: int
) -> tuple[CarFollowingWindows, NDArray[np.int64]]:
    """All windows, or ``n`` of them drawn at random (for tests and quick looks).

    Parameters
    ----------
    windows : CarFollowingWindows
        ``W`` windows.
    n : int or None
        How many to keep (all when None or ``n >= W``).
    seed : int
        Seeds the draw (``numpy.random.default_rng``).

    Returns
    -------
    windows : CarFollowingWindows
        The kept windows, in their order.
    labels : ndarray of int64, shape (n,)
        Index of each in ``windows``: the window's name in the tables.
    """
    if n is None or n >= len(windows):
        labels = np.arange(len(windows), dtype=np.int64)
    else:
        pick = np.random.default_rng(seed).permutation(len(windows))[:n]
        labels = np.sort(pick).astype(np.int64)
    return windows.take(labels), labels
