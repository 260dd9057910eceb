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

import torch

__all__ = ["eager_slice"]


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
