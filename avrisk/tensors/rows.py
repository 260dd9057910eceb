"""Replacing some rows of a batch held in nested containers of tensors.

A batch of rollouts carries its state as a tree: tensors with the batch as
their leading dimension, inside tuples, named tuples, lists, dicts and
dataclasses, with ``None`` and other constants along the way (the simulator's
carry, the actors' states). :func:`replace_rows` puts the rows of a smaller
batch of the same structure into chosen rows of it, to restart some rollouts
while the others go on.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
from torch import Tensor

__all__ = ["replace_rows"]


def replace_rows(tree: Any, rows: Tensor, fresh: Any) -> Any:
    """``tree`` with the rows where ``rows`` is true taken from ``fresh``.

    Parameters
    ----------
    tree : nested containers of tensors
        A batch of ``B``: every tensor has ``B`` as its leading dimension, or
        is shared by the whole batch (for example one parameter vector for
        every rollout).
    rows : Tensor of bool, shape (B,)
        The rows to replace; ``n`` of them are true.
    fresh : same structure as ``tree``
        A batch of ``n``, the new rows in the order of ``rows``: its tensors
        have ``n`` as their leading dimension where ``tree``'s have ``B``;
        shared tensors and other constants must equal ``tree``'s.

    Returns
    -------
    same structure as ``tree``
        New tensors where rows were replaced (``tree`` is not modified).

    Raises
    ------
    ValueError
        If the structures differ, or a shared tensor or constant differs
        between ``tree`` and ``fresh``.

    Examples
    --------
    >>> tree = {"v": torch.zeros(4), "pair": (torch.ones(4, 2), None), "k": 3}
    >>> rows = torch.tensor([False, True, False, True])
    >>> pair = (torch.zeros(2, 2), None)
    >>> fresh = {"v": torch.tensor([7.0, 8.0]), "pair": pair, "k": 3}
    >>> out = replace_rows(tree, rows, fresh)
    >>> out["v"].tolist(), out["pair"][0][:, 0].tolist()
    ([0.0, 7.0, 0.0, 8.0], [1.0, 0.0, 1.0, 0.0])
    """
    if rows.dim() != 1 or rows.dtype != torch.bool:
        raise ValueError(
            f"rows must be a bool tensor of shape (B,); got {rows.dtype} "
            f"of shape {tuple(rows.shape)}"
        )
    n_rows, n_fresh = rows.shape[0], int(rows.sum())
    if n_fresh == n_rows:  # every row restarts: shared parts are equal
        return fresh
    return _replace(tree, rows, fresh, n_rows, n_fresh, "carry")


def _replace(
    old: Any, rows: Tensor, new: Any, n_rows: int, n_new: int, where: str
) -> Any:
    if isinstance(old, Tensor):
        if not isinstance(new, Tensor):
            raise ValueError(f"{where}: a tensor replaced by {type(new).__name__}")
        batched = old.dim() > 0 and new.dim() > 0
        if batched and old.shape[0] == n_rows and new.shape[0] == n_new:
            if old.shape[1:] != new.shape[1:]:
                raise ValueError(
                    f"{where}: rows of shape {tuple(new.shape[1:])} for rows of "
                    f"shape {tuple(old.shape[1:])}"
                )
            out = old.clone()
            out[rows] = new.to(old.dtype)
            return out
        if old.shape == new.shape and torch.equal(old, new):
            return old  # shared by the whole batch
        raise ValueError(
            f"{where}: shape {tuple(old.shape)} is neither per row (leading "
            f"dimension {n_rows}) nor the same for every row"
        )
    if type(old) is not type(new):
        raise ValueError(
            f"{where}: {type(old).__name__} replaced by {type(new).__name__}"
        )
    if isinstance(old, tuple | list):
        if len(old) != len(new):
            raise ValueError(f"{where}: {len(old)} items replaced by {len(new)}")
        items = [
            _replace(a, rows, b, n_rows, n_new, f"{where}[{i}]")
            for i, (a, b) in enumerate(zip(old, new, strict=True))
        ]
        return type(old)(*items) if hasattr(old, "_fields") else type(old)(items)
    if isinstance(old, dict):
        if old.keys() != new.keys():
            raise ValueError(f"{where}: keys {sorted(old)} replaced by {sorted(new)}")
        return {
            k: _replace(v, rows, new[k], n_rows, n_new, f"{where}[{k!r}]")
            for k, v in old.items()
        }
    if dataclasses.is_dataclass(old) and not isinstance(old, type):
        return dataclasses.replace(
            old,
            **{
                f.name: _replace(
                    getattr(old, f.name),
                    rows,
                    getattr(new, f.name),
                    n_rows,
                    n_new,
                    f"{where}.{f.name}",
                )
                for f in dataclasses.fields(old)
                if f.init
            },
        )
    if old is new or old == new:
        return old
    raise ValueError(f"{where}: {old!r} replaced by {new!r}")
