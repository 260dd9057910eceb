import numpy as np
import pytest
import torch

from avrisk.learning.ngsim.samples import LateralPairs


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


@pytest.fixture
def one_thread():
    """torch on one thread during the test (bit-reproducible CPU kernels)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
