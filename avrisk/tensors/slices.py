"""Eager work on a CPU in cache-sized slices of the batch.

Element-wise work over a large batch makes temporaries of the batch's size:
on a CPU they leave the cache (and, past glibc's mmap threshold, are mapped,
page-faulted and zeroed afresh by every operation), so the simulator's ray
casting and the camera work through the batch in slices. On a GPU a slice is
only more kernel launches, and under ``torch.compile`` fused kernels stream
the batch: both take the whole batch at once. Results do not depend on it:
the work is element-wise along the batch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
from torch import Tensor

__all__ = ["eager_slice", "in_slices"]


def eager_slice(
    batch: int, per_rollout: int, budget: int, device: torch.device
) -> int | None:
    """Rollouts per slice, or None to take the batch whole.

    Parameters
    ----------
    batch : int
        Rollouts in the batch.
    per_rollout : int
        Elements of the largest temporary per rollout.
    budget : int
        Elements per slice that keep the temporaries in the cache.
    device : torch.device
        Where the work runs: only a CPU slices.

    Returns
    -------
    int or None
        ``max(1, budget // per_rollout)`` rollouts per slice when eager on a
        CPU and the batch is larger; otherwise None.

    Examples
    --------
    >>> cpu, gpu = torch.device("cpu"), torch.device("cuda")
    >>> eager_slice(1000, 600, 1 << 17, cpu), eager_slice(1000, 600, 1 << 17, gpu)
    (218, None)
    >>> eager_slice(100, 600, 1 << 17, cpu) is None
    True
    """
    if torch.compiler.is_compiling() or device.type != "cpu":
        return None
    step = max(1, budget // max(1, per_rollout))
    return step if batch > step else None


def in_slices(
    fn: Callable[..., Any],
    args: Sequence[Any],
    per_rollout: int,
    budget: int,
    device: torch.device,
) -> Any:
    """``fn(*args)``, on slices of the batch where :func:`eager_slice` says so.

    Parameters
    ----------
    fn : callable
        Element-wise along the batch; returns a tensor or a tensor dataclass
        (anything with a ``cat`` class method) with the batch first.
    args : sequence
        Tensors or tensor dataclasses with the batch first (``shape[0]``).
    per_rollout, budget, device
        As for :func:`eager_slice`.

    Returns
    -------
    Any
        ``fn(*args)``, the slices' results concatenated along the batch.

    Examples
    --------
    >>> x = torch.arange(6.0)
    >>> in_slices(torch.square, (x,), 1, 2, torch.device("cpu")).tolist()
    [0.0, 1.0, 4.0, 9.0, 16.0, 25.0]
    """
    n = args[0].shape[0]
    step = eager_slice(n, per_rollout, budget, device)
    if step is None:
        return fn(*args)
    parts = [fn(*(a[i : i + step] for a in args)) for i in range(0, n, step)]
    if isinstance(parts[0], Tensor):
        return torch.cat(parts)
    return type(parts[0]).cat(parts)
