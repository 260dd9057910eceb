"""Count the tensor operations a piece of code dispatches (a regression guard).

The simulator's speed on CPU (eager) and the number of kernels on a GPU both
grow with the number of tensor operations per step; a per-vehicle or
per-rollout Python loop shows as an op count that grows with the batch.
:class:`OpCounter` counts every ATen operation dispatched inside its ``with``
block, by name (views and in-place updates included, nested decompositions
not: one call of ``torch.where`` is one op).

Examples
--------
>>> import torch
>>> with OpCounter() as ops:
...     _ = torch.ones(3) * 2.0 + 1.0
>>> ops.total, ops.counts["aten.mul.Tensor"]
(3, 1)
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from torch.utils._python_dispatch import TorchDispatchMode

__all__ = ["OpCounter"]


class OpCounter(TorchDispatchMode):
    """Counts dispatched ATen operations by overload name.

    Attributes
    ----------
    counts : collections.Counter
        ``"aten.mul.Tensor"`` -> number of calls.
    """

    def __init__(self) -> None:
        super().__init__()
        self.counts: Counter[str] = Counter()

    def __torch_dispatch__(
        self, func: Any, types: Any, args: Any = (), kwargs: Any = None
    ) -> Any:
        self.counts[str(func)] += 1
        return func(*args, **(kwargs or {}))

    @property
    def total(self) -> int:
        """All operations counted."""
        return sum(self.counts.values())

    def by_op(self) -> Counter[str]:
        """Counts by operation, overloads merged (``"mul"``, ``"where"``)."""
        merged: Counter[str] = Counter()
        for name, n in self.counts.items():
            merged[name.split(".")[1]] += n
        return merged
