"""The paired black box and the final weighted sample with both outcomes.

:class:`MinOfPair` makes a paired black box (``(f_A, f_B)`` per row) the
engine's ordinary one, ``min(f_A, f_B)``, both values recorded beside it;
:class:`FinalStageTap` keeps the final stage's chunks as a run evaluates or
replays them, and gives the :class:`PairedSample` of :mod:`avrisk.rare.paired`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from avrisk.rare.families.base import FloatArray
from avrisk.rare.mixture_controls import mixture_controls
from avrisk.rare.problem import FINAL_STAGE, BatchFunction, InvalidOutputError
from avrisk.rare.stages import BatchCache, BatchRecorder, StageBatch

__all__ = ["PAIR_COLUMNS", "FinalStageTap", "MinOfPair", "PairedSample"]

#: The recorded columns of each version's outcome, A's first.
PAIR_COLUMNS = ("f_a", "f_b")


@dataclass(frozen=True)
class PairedSample:
    """The final weighted sample with both versions' outcomes.

    Attributes
    ----------
    log_w : ndarray of shape (n,)
        ``log p0 - log q`` of each sample.
    f_a, f_b : ndarray of shape (n,)
        Each version's value (NaN where the evaluation failed).
    failed : ndarray of bool, shape (n,)
        Samples whose evaluation failed (counted safe for both versions).
    controls : ndarray of shape (n, J)
        The proposal's centred control variates at each sample
        (:func:`~avrisk.rare.mixture_controls.mixture_controls`; ``J = 0``:
        none).
    """

    log_w: FloatArray
    f_a: FloatArray
    f_b: FloatArray
    failed: np.ndarray
    controls: FloatArray


class MinOfPair:
    """The black box ``min(f_A, f_B)`` of a paired one, both values kept.

    Parameters
    ----------
    pair : callable
        ``pair(x)`` (or ``pair(x, seeds=...)`` with ``needs_seeds = True``)
        returns an ``(n, 2)`` array of ``(f_A, f_B)``, or a mapping with it
        under ``"f"`` and other per-sample outputs (``"status"`` ...) as
        ``(n,)`` arrays.

    Returns (when called)
    ---------------------
    dict
        ``f``: ``min(f_A, f_B)`` (NaN where either is), ``f_a``, ``f_b``,
        and the pair's other outputs.

    Attributes
    ----------
    device : str or None
        The pair's ``device``, if it has one (a worker names it in
        :data:`~avrisk.rare.parallel.EVALUATED_BY`).
    """

    def __init__(self, pair: BatchFunction) -> None:
        self.pair = pair
        self.needs_seeds = bool(getattr(pair, "needs_seeds", False))
        self.device: str | None = getattr(pair, "device", None)

    def __call__(
        self, x: FloatArray, seeds: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """``f``: ``min(f_A, f_B)`` (NaN where either is), ``f_a``, ``f_b``, the rest.

        Raises
        ------
        InvalidOutputError
            If the pair's values are not of shape (n, 2).
        """
        out = self.pair(x, seeds=seeds) if self.needs_seeds else self.pair(x)
        extras: dict[str, Any] = {}
        if isinstance(out, Mapping):
            extras = {k: v for k, v in out.items() if k != "f"}
            out = out["f"]
        values = np.asarray(out, dtype=np.float64)
        if values.shape != (len(x), 2):
            raise InvalidOutputError(
                f"a paired f must return an array of shape ({len(x)}, 2) (f_A, "
                f"f_B) for {len(x)} input rows; got shape {values.shape}"
            )
        f_a, f_b = values[:, 0], values[:, 1]
        return {"f": np.minimum(f_a, f_b), "f_a": f_a, "f_b": f_b, **extras}


class FinalStageTap:
    """Keeps the final stage's chunks, evaluated or replayed, on their way.

    Wraps a run's ``on_batch`` and ``cache`` (either may be None): every
    chunk of :data:`~avrisk.rare.problem.FINAL_STAGE` that is evaluated or
    replayed is kept (a re-evaluated chunk replaces its replay), and passed on
    unchanged; the others pass through. The estimator is not changed: the tap
    sees what the run's record sees.
    """

    def __init__(
        self, on_batch: BatchRecorder | None = None, cache: BatchCache | None = None
    ) -> None:
        self._on_batch = on_batch
        self._cache = cache
        self.chunks: dict[int, StageBatch] = {}

    def record(self, batch: StageBatch) -> None:
        """``on_batch`` of the run."""
        if batch.stage == FINAL_STAGE:
            self.chunks[batch.chunk] = batch
        if self._on_batch is not None:
            self._on_batch(batch)

    def replay(self, stage: int, chunk: int) -> StageBatch | None:
        """``cache`` of the run."""
        batch = self._cache(stage, chunk) if self._cache is not None else None
        if batch is not None and stage == FINAL_STAGE:
            self.chunks[chunk] = batch
        return batch

    def sample(self, n: int, proposal: Any = None) -> PairedSample:
        """The first ``n`` samples of the final stage (its chunks in order).

        ``proposal``: the distribution they were drawn from, whose mixture
        components give the sample's control variates (none without it).

        Raises
        ------
        RuntimeError
            If a chunk is missing or lacks the pair's columns.
        """
        ordered, total = [], 0
        while total < n:
            batch = self.chunks.get(len(ordered))
            if batch is None or not set(PAIR_COLUMNS) <= set(batch.extras):
                raise RuntimeError(
                    f"chunk {len(ordered)} of the final stage was not seen with both "
                    f"versions' values ({', '.join(PAIR_COLUMNS)})"
                )
            ordered.append(batch)
            total += batch.values.size

        def column(get: Callable[[StageBatch], np.ndarray]) -> np.ndarray:
            return np.concatenate([get(b) for b in ordered])[:n]

        return PairedSample(
            column(lambda b: b.log_p0 - b.log_q),
            column(lambda b: np.asarray(b.extras["f_a"], dtype=np.float64)),
            column(lambda b: np.asarray(b.extras["f_b"], dtype=np.float64)),
            column(lambda b: b.failed),
            mixture_controls(proposal, column(lambda b: b.x)),
        )
