"""Car-following windows for tests: the recorded profiles given, the rest filled in."""

import numpy as np

from avrisk.learning.replay import CarFollowingWindows


def recorded_windows(v_f, v_l, gap, has_lateral=None):
    """Windows of ``v_f``, ``v_l``, ``gap`` (each of shape (W, T+1)) in lane 2.

    Cars 4.5 m long, the follower 1.9 m wide, no lateral offset or heading;
    ``has_lateral`` (bool, shape (W,)) defaults to all False.
    """
    v_f, v_l, gap = (np.asarray(a, dtype=float) for a in (v_f, v_l, gap))
    n = v_f.shape[0]
    return CarFollowingWindows(
        v_f=v_f,
        v_l=v_l,
        gap=gap,
        offset=np.zeros_like(v_f),
        has_lateral=np.zeros(n, bool) if has_lateral is None else has_lateral,
        len_f=np.full(n, 4.5),
        len_l=np.full(n, 4.5),
        width_f=np.full(n, 1.9),
        lane=np.full(n, 2),
        heading=np.zeros(n),
    )
