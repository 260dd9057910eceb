"""Product of independent exponential-family blocks.

Coordinates of the blocks are concatenated in order; log-densities add; the
sufficient statistic, natural and mean parameters are concatenations; the CE
projection splits the target mean parameter by block and projects each block
on its own (the constrained problem separates because the box is a product).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray, as_sample_array


class Product(ExponentialFamily):
    """Independent blocks ``X = (X_1, ..., X_k)``, each its own family.

    Parameters
    ----------
    blocks : sequence of ExponentialFamily
        The blocks, in coordinate order.

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.rare import ScaledBeta, FixedCovNormal
    >>> base = Product([ScaledBeta(2, 2, lo=80, scale=40),
    ...                 FixedCovNormal(np.zeros(2), cov=np.eye(2))])
    >>> base.dim, base.sample(5, np.random.default_rng(0)).shape
    (3, (5, 3))
    """

    def __init__(self, blocks: Sequence[ExponentialFamily]) -> None:
        self.blocks = tuple(blocks)
        if not self.blocks:
            raise ValueError("Product needs at least one block")
        for i, block in enumerate(self.blocks):
            if not isinstance(block, ExponentialFamily):
                raise TypeError(f"block {i} is not an ExponentialFamily: {block!r}")
        self._x_cuts = np.cumsum([b.dim for b in self.blocks])[:-1]
        self._t_cuts = np.cumsum([b.n_stats for b in self.blocks])[:-1]
        self.dim = int(sum(b.dim for b in self.blocks))
        self.n_stats = int(sum(b.n_stats for b in self.blocks))

    def _split_x(self, x: FloatArray) -> list[FloatArray]:
        return np.split(as_sample_array(x, self.dim), self._x_cuts, axis=1)

    def _split_t(self, t: FloatArray) -> list[FloatArray]:
        return np.split(
            np.asarray(t, dtype=np.float64).reshape(self.n_stats), self._t_cuts
        )

    def sample(self, n: int, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` samples, shape (n, D); each block from its own child of ``rng``.

        Separate generators keep row ``i`` independent of ``n``: drawing block
        after block from one stream would shift block 2's draws with ``n``.
        """
        streams = rng.spawn(len(self.blocks))
        parts = [b.sample(n, s) for b, s in zip(self.blocks, streams, strict=True)]
        return np.concatenate(parts, axis=1)

    def log_prob(self, x: FloatArray) -> FloatArray:
        """Sum of the blocks' log-densities, shape (n,)."""
        return np.sum(
            [
                b.log_prob(xb)
                for b, xb in zip(self.blocks, self._split_x(x), strict=True)
            ],
            axis=0,
        )

    def sufficient_stat(self, x: FloatArray) -> FloatArray:
        """Concatenated block statistics, shape (n, n_stats)."""
        parts = [
            b.sufficient_stat(xb)
            for b, xb in zip(self.blocks, self._split_x(x), strict=True)
        ]
        return np.concatenate(parts, axis=1)

    def to_standard_normal(self, x: FloatArray) -> FloatArray:
        """Each block's map on its columns, shape (n, D)."""
        parts = [
            b.to_standard_normal(xb)
            for b, xb in zip(self.blocks, self._split_x(x), strict=True)
        ]
        return np.concatenate(parts, axis=1)

    def from_standard_normal(self, z: FloatArray) -> FloatArray:
        """Each block's inverse map on its columns, shape (n, D)."""
        parts = [
            b.from_standard_normal(zb)
            for b, zb in zip(self.blocks, self._split_x(z), strict=True)
        ]
        return np.concatenate(parts, axis=1)

    @property
    def natural_params(self) -> FloatArray:
        """Concatenated natural parameters."""
        return np.concatenate([b.natural_params for b in self.blocks])

    def with_natural_params(self, theta: FloatArray) -> Product:
        """Each block at its slice of ``theta``."""
        parts = self._split_t(theta)
        return Product(
            [b.with_natural_params(t) for b, t in zip(self.blocks, parts, strict=True)]
        )

    def exact_params(self) -> FloatArray:
        """Concatenated exact parameters of the blocks, shape (n_stats,)."""
        return np.concatenate([b.exact_params() for b in self.blocks])

    def with_exact_params(self, params: FloatArray) -> Product:
        """Each block at its slice of ``params``."""
        parts = self._split_t(params)
        return Product(
            [b.with_exact_params(p) for b, p in zip(self.blocks, parts, strict=True)]
        )

    def log_partition(self) -> float:
        """Sum of the blocks' log-partitions."""
        return float(sum(b.log_partition() for b in self.blocks))

    def mean_param(self) -> FloatArray:
        """Concatenated mean parameters."""
        return np.concatenate([b.mean_param() for b in self.blocks])

    def project(self, m: FloatArray) -> Product:
        """Project each block on its slice of ``m``."""
        parts = self._split_t(m)
        return Product([b.project(t) for b, t in zip(self.blocks, parts, strict=True)])

    def in_search_box(self) -> bool:
        """Whether every block is in its search box."""
        return all(b.in_search_box() for b in self.blocks)

    def searched_coordinates(self) -> np.ndarray:
        """The blocks' searched coordinates, concatenated, shape (D,)."""
        return np.concatenate([b.searched_coordinates() for b in self.blocks])

    def to_dict(self) -> dict[str, Any]:
        """Family name and the blocks' descriptions."""
        return {"family": "Product", "blocks": [b.to_dict() for b in self.blocks]}
