from dataclasses import dataclass
from typing import NamedTuple

import pytest
import torch

from avrisk.tensors.rows import replace_rows
from avrisk.tensors.tensors import TensorDataclass


@dataclass(frozen=True)
class Pose(TensorDataclass):
    x: torch.Tensor
    tag: str = "pose"


class Memory(NamedTuple):
    shared: torch.Tensor
    per_row: torch.Tensor | None


def batch(b, fill):
    return (
        Pose(torch.full((b, 3), fill)),
        Memory(torch.arange(4.0), torch.full((b, 2), fill)),
        [None, {"k": torch.full((b,), fill, dtype=torch.int64)}],
    )


def test_the_chosen_rows_come_from_the_fresh_batch_in_order():
    tree = batch(5, 0.0)
    fresh = batch(2, 1.0)
    fresh[1].per_row[:] = torch.tensor([[1.0], [2.0]])
    rows = torch.tensor([False, True, False, False, True])
    out = replace_rows(tree, rows, fresh)
    assert type(out[0]) is Pose and type(out[1]) is Memory and out[0].tag == "pose"
    assert out[0].x[:, 0].tolist() == [0.0, 1.0, 0.0, 0.0, 1.0]
    assert out[1].per_row[:, 1].tolist() == [0.0, 1.0, 0.0, 0.0, 2.0]
    assert out[1].shared is tree[1].shared  # shared by every row: kept
    assert out[2][1]["k"].tolist() == [0, 1, 0, 0, 1]
    assert out[2][1]["k"].dtype == torch.int64
    assert tree[0].x.sum() == 0  # the input is not modified


def test_every_row_restarted_is_the_fresh_batch():
    fresh = batch(3, 1.0)
    assert replace_rows(batch(3, 0.0), torch.ones(3, dtype=torch.bool), fresh) is fresh


@pytest.mark.parametrize(
    "spoil, match",
    [
        (lambda t: t[:1] + (Memory(torch.zeros(4), t[1].per_row),) + t[2:], "same"),
        (lambda t: (Pose(t[0].x, tag="other"),) + t[1:], "replaced by"),
        (lambda t: t[:2] + ([None],), "items"),
        (lambda t: (t[0].x,) + t[1:], "replaced by"),
    ],
)
def test_a_fresh_batch_of_another_structure_or_shared_value_is_refused(spoil, match):
    rows = torch.tensor([True, False, False])
    with pytest.raises(ValueError, match=match):
        replace_rows(batch(3, 0.0), rows, spoil(batch(1, 1.0)))
