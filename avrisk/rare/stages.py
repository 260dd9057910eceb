"""Sampling and evaluating one stage of a run, chunk by chunk.

A *stage* is one batch of ``n`` samples from one distribution: a CE search
iteration or the final estimation stage. Its samples are drawn in chunks of
:data:`~avrisk.rare.problem.SAMPLE_CHUNK` rows from per-chunk generators, so
memory stays bounded for any ``n`` and each chunk can be recorded as it is
done (``on_batch``) and, when a run resumes, replayed from that record
(``cache``) instead of being evaluated again. A replayed chunk holds the same
numbers as a fresh one, so a resumed run ends with the same result.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.problem import (
    SAMPLE_CHUNK,
    RareEventProblem,
    chunk_rng,
    sample_seeds,
)


class StageBatch(NamedTuple):
    """One evaluated chunk of a stage: everything a samples table records.

    Attributes
    ----------
    stage : int
        0 for the final stage, ``k + 1`` for CE iteration ``k``.
    chunk : int
        Index of the chunk within the stage.
    ids : ndarray of int64, shape (m,)
        Sample ids within the stage.
    x : ndarray of shape (m, D)
        Samples.
    values : ndarray of shape (m,)
        ``f(x)``.
    extras : dict of str to ndarray of shape (m,)
        Other outputs of ``f`` (recorded, not used).
    log_p0, log_q : ndarray of shape (m,)
        Log-densities under the base and under the distribution sampled.
    seeds : ndarray of int64, shape (m,)
        Per-sample seeds passed to a seeded ``f``.
    """

    stage: int
    chunk: int
    ids: np.ndarray
    x: FloatArray
    values: FloatArray
    extras: dict[str, np.ndarray]
    log_p0: FloatArray
    log_q: FloatArray
    seeds: np.ndarray


#: Called with each newly evaluated chunk (recording, progress).
BatchRecorder = Callable[[StageBatch], None]
#: Returns the recorded chunk ``(stage, chunk)`` of an interrupted run, or None.
BatchCache = Callable[[int, int], StageBatch | None]


class StageResult(NamedTuple):
    """What the estimators need from a stage.

    Attributes
    ----------
    values : ndarray of shape (n,)
    log_w : ndarray of shape (n,)
        ``log p0 - log q``.
    stats : ndarray of shape (n, K) or None
        Sufficient statistics under the sampled family, when asked for.
    """

    values: FloatArray
    log_w: FloatArray
    stats: FloatArray | None


def run_stage(
    problem: RareEventProblem,
    proposal: ExponentialFamily | DefensiveMixture,
    n: int,
    *,
    seed: int,
    stage: int,
    keep_stats: bool = False,
    on_batch: BatchRecorder | None = None,
    cache: BatchCache | None = None,
) -> StageResult:
    """Draw ``n`` samples of ``proposal`` for ``stage`` and evaluate ``f``."""
    values, log_w, stats = [], [], []
    for chunk, start in enumerate(range(0, n, SAMPLE_CHUNK)):
        size = min(SAMPLE_CHUNK, n - start)
        batch = cache(stage, chunk) if cache is not None else None
        if batch is None or batch.values.shape != (size,):
            batch = _evaluate_chunk(problem, proposal, seed, stage, chunk, start, size)
            if on_batch is not None:
                on_batch(batch)
        values.append(batch.values)
        log_w.append(batch.log_p0 - batch.log_q)
        if keep_stats:
            stats.append(proposal.sufficient_stat(batch.x))
    return StageResult(
        np.concatenate(values),
        np.concatenate(log_w),
        np.concatenate(stats) if keep_stats else None,
    )


def _evaluate_chunk(
    problem: RareEventProblem,
    proposal: ExponentialFamily | DefensiveMixture,
    seed: int,
    stage: int,
    chunk: int,
    start: int,
    size: int,
) -> StageBatch:
    ids = np.arange(start, start + size, dtype=np.int64)
    x = proposal.sample(size, chunk_rng(seed, stage, chunk))
    seeds = sample_seeds(seed, stage, ids)
    values, extras = problem.evaluate(x, seeds)
    log_p0 = problem.base.log_prob(x)
    log_q = log_p0 if proposal is problem.base else proposal.log_prob(x)
    return StageBatch(stage, chunk, ids, x, values, extras, log_p0, log_q, seeds)
