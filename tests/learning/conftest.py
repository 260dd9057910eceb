import numpy as np
import pytest

from avrisk.learning.ngsim_samples import LateralPairs


@pytest.fixture
def lateral_stub():
    """Factory of LateralPairs with given follower ids and columns, zeros elsewhere."""

    def make(follower_ids, **columns):
        n = len(follower_ids)
        ints = {"leader_id", "frame", "vehicle_class", "lane", "leader_class"}
        cols = {
            "pair_id": np.array([f"{v}-0" for v in follower_ids]),
            "follower_id": np.array(follower_ids),
        }
        for name in LateralPairs.__dataclass_fields__:
            if name not in cols:
                cols[name] = np.zeros(n, np.int64) if name in ints else np.zeros(n)
        cols.update(columns)
        return LateralPairs(**cols)

    return make
