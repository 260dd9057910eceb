"""A small base for frozen dataclasses whose fields are tensors of one shape.

It gives the batch helpers that state, parameter and action containers share:
indexing along the leading (batch) dimensions, device and dtype moves,
elementwise selection between two instances, stacking and concatenation.
Fields that are not tensors (or ``None``) are carried along unchanged.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, Self

import torch
from torch import Tensor

__all__ = ["TensorDataclass"]


class TensorDataclass:
    """Mixin for ``@dataclass(frozen=True)`` classes of same-shape tensors.

    Subclasses are frozen dataclasses; every tensor field shares the same
    leading shape (the "batch shape"; for vehicle data ``(B, A)``).
    """

    def _tensors(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}  # type: ignore[arg-type]

    def map(self, fn: Callable[[Tensor], Tensor]) -> Self:
        """Apply ``fn`` to every tensor field; other fields are kept.

        Parameters
        ----------
        fn : callable
            Tensor to tensor.

        Returns
        -------
        Same type as ``self``.
        """
        return dataclasses.replace(
            self,  # type: ignore[type-var]
            **{k: fn(v) for k, v in self._tensors().items() if isinstance(v, Tensor)},
        )

    def __getitem__(self, index: Any) -> Self:
        """Index every tensor field along its leading dimensions."""
        return self.map(lambda t: t[index])

    def to(
        self, device: str | torch.device | None = None, dtype: torch.dtype | None = None
    ) -> Self:
        """Move floating fields to ``dtype`` and every field to ``device``.

        Integer and boolean fields keep their dtype.
        """

        def move(t: Tensor) -> Tensor:
            if dtype is not None and t.is_floating_point():
                return t.to(device=device, dtype=dtype)
            return t.to(device=device)

        return self.map(move)

    def where(self, mask: Tensor, other: Self) -> Self:
        """Take ``self`` where ``mask`` is true and ``other`` elsewhere.

        Parameters
        ----------
        mask : Tensor of bool
            Broadcastable against the leading dimensions of the fields; a
            rollout mask of shape (B,) is expanded over the trailing ones.
        other : same type as ``self``

        Returns
        -------
        Same type as ``self``.
        """
        mine, theirs = self._tensors(), other._tensors()
        out = {}
        for k, v in mine.items():
            if isinstance(v, Tensor):
                m = mask.reshape(mask.shape + (1,) * (v.dim() - mask.dim()))
                out[k] = torch.where(m, v, theirs[k])
        return dataclasses.replace(self, **out)  # type: ignore[type-var]

    @classmethod
    def stack(cls, items: Sequence[Self], dim: int = 0) -> Self:
        """Stack instances along a new dimension ``dim`` of every field."""
        return cls._combine(items, lambda ts: torch.stack(ts, dim))

    @classmethod
    def cat(cls, items: Sequence[Self], dim: int = 0) -> Self:
        """Concatenate instances along the existing dimension ``dim``."""
        return cls._combine(items, lambda ts: torch.cat(ts, dim))

    @classmethod
    def _combine(
        cls, items: Sequence[Self], fn: Callable[[list[Tensor]], Tensor]
    ) -> Self:
        if not items:
            raise ValueError(f"{cls.__name__}: need at least one item to combine")
        first = items[0]
        out = {}
        for k, v in first._tensors().items():
            if isinstance(v, Tensor):
                out[k] = fn([getattr(it, k) for it in items])
        return dataclasses.replace(first, **out)  # type: ignore[type-var]

    @property
    def shape(self) -> torch.Size:
        """The common shape of the tensor fields."""
        for v in self._tensors().values():
            if isinstance(v, Tensor):
                return v.shape
        raise ValueError(f"{type(self).__name__} has no tensor field")

    def _check_same_shape(self) -> None:
        shapes = {
            k: tuple(v.shape)
            for k, v in self._tensors().items()
            if isinstance(v, Tensor)
        }
        if len(set(shapes.values())) > 1:
            raise ValueError(
                f"{type(self).__name__}: every field must have the same shape; "
                f"got {shapes}"
            )
