"""Sampling and evaluating one stage of a run, chunk by chunk.

A *stage* is one batch of ``n`` samples from one distribution: a CE search
iteration or the final estimation stage. Its samples are drawn in chunks of
:data:`~avrisk.rare.problem.SAMPLE_CHUNK` rows from per-chunk generators, so
memory stays bounded for any ``n``. The chunks go to an evaluator
(:mod:`avrisk.rare.evaluation`) that may return them in any order; each is
recorded as it comes back (``on_batch``) and, when a run resumes, replayed from
that record (``cache``) instead of being evaluated again. A replayed chunk
holds the same numbers as a fresh one, so a resumed run ends with the same
result. A recorded chunk with failed samples (``status != 0``) is evaluated
again on resume.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

import numpy as np

from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.evaluation import (
    EvalResult,
    EvalTask,
    Evaluator,
    LocalEvaluator,
    failed_mask,
)
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.problem import (
    SAMPLE_CHUNK,
    RareEventProblem,
    chunk_rng,
    sample_seeds,
)


class ChunkDraw(NamedTuple):
    """What a chunk's samples were drawn from: its stage's proposal and the run seed.

    ``x`` of chunk ``j`` (``m`` rows) of stage ``s`` is
    ``chunk_task(proposal, seed, s, j, m).x``, whatever process drew it.
    """

    proposal: ExponentialFamily | DefensiveMixture
    seed: int


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
    draw : ChunkDraw or None
        How ``x`` was drawn, when it is a fresh draw of the stage's proposal
        (so it can be drawn again); None for given points (MCMC moves).
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
    draw: ChunkDraw | None = None

    @property
    def failed(self) -> np.ndarray:
        """Bool (m,): samples whose evaluation failed (``status != 0``)."""
        return failed_mask(self.values, self.extras)


#: Called with each newly evaluated chunk (recording, progress).
BatchRecorder = Callable[[StageBatch], None]
#: Returns the recorded chunk ``(stage, chunk)`` of an interrupted run, or None.
BatchCache = Callable[[int, int], StageBatch | None]


class StageResult(NamedTuple):
    """What the estimators need from a stage.

    Attributes
    ----------
    values : ndarray of shape (n,)
        ``f`` of every sample (NaN where ``failed``).
    log_w : ndarray of shape (n,)
        ``log p0 - log q``.
    stats : ndarray of shape (n, K) or None
        Sufficient statistics under the sampled family, when asked for.
    failed : ndarray of bool, shape (n,)
        Samples whose evaluation failed (see :mod:`avrisk.rare.evaluation`).
    stopped_by : str or None
        The stopping rule that ended the stage early (then ``n`` is the
        prefix of chunks done), or None.
    """

    values: FloatArray
    log_w: FloatArray
    stats: FloatArray | None
    failed: np.ndarray
    stopped_by: str | None = None


#: ``stop(batches)``: why to end a stage after this contiguous prefix of its
#: chunks, or None (see :mod:`avrisk.rare.stopping`).
StageStop = Callable[[list[StageBatch], int], str | None]


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
    evaluator: Evaluator | None = None,
    stop: StageStop | None = None,
) -> StageResult:
    """Draw ``n`` samples of ``proposal`` for ``stage`` and evaluate ``f``.

    Parameters
    ----------
    problem : RareEventProblem
    proposal : ExponentialFamily or DefensiveMixture
        The distribution sampled.
    n : int
        Samples of the stage.
    seed : int
        Run seed.
    stage : int
        Stage number (sample ``i`` depends only on ``seed``, ``stage``, ``i``).
    keep_stats : bool, default=False
        Also return the sufficient statistics of the samples under ``proposal``.
    on_batch : callable, optional
        Called with each newly evaluated chunk, in the order they come back.
    cache : callable, optional
        ``cache(stage, chunk)``: a recorded chunk of an interrupted run, or None.
    evaluator : Evaluator, optional
        Where ``f`` runs; default :class:`~avrisk.rare.evaluation.LocalEvaluator`.
    stop : callable, optional
        ``stop(prefix, next_size)``: checked on the contiguous prefix of
        chunks done after each chunk; a reason ends the stage there.

    Returns
    -------
    StageResult
    """
    sizes = [min(SAMPLE_CHUNK, n - start) for start in range(0, n, SAMPLE_CHUNK)]
    batches: dict[int, StageBatch] = {}
    for chunk, size in enumerate(sizes):
        batch = cache(stage, chunk) if cache is not None else None
        if batch is not None and batch.values.shape == (size,):
            if not batch.failed.any():
                batches[chunk] = batch

    def tasks() -> Iterator[EvalTask]:
        for chunk, size in enumerate(sizes):
            if chunk not in batches:
                yield chunk_task(proposal, seed, stage, chunk, size)

    def prefix() -> list[StageBatch]:
        done = []
        while len(done) in batches:
            done.append(batches[len(done)])
        return done

    def why_stop() -> str | None:
        if stop is None:
            return None
        done = prefix()
        if not done or len(done) == len(sizes):
            return None
        return stop(done, sizes[len(done)])

    stopped_by = why_stop()
    if stopped_by is None:
        for result in (evaluator or LocalEvaluator()).evaluate(problem, tasks()):
            batch = _stage_batch(problem, ChunkDraw(proposal, seed), result)
            batches[batch.chunk] = batch
            if on_batch is not None:
                on_batch(batch)
            stopped_by = why_stop()
            if stopped_by is not None:
                break
    if stopped_by is not None:
        sizes = sizes[: len(prefix())]
    if len(batches) < len(sizes):
        missing = sorted(set(range(len(sizes))) - set(batches))
        raise RuntimeError(
            f"the evaluator returned no result for chunks {missing} of stage {stage}"
        )
    ordered = [batches[chunk] for chunk in range(len(sizes))]
    return StageResult(
        np.concatenate([b.values for b in ordered]),
        np.concatenate([b.log_p0 - b.log_q for b in ordered]),
        (
            np.concatenate([proposal.sufficient_stat(b.x) for b in ordered])
            if keep_stats
            else None
        ),
        np.concatenate([b.failed for b in ordered]),
        stopped_by,
    )


def chunk_task(
    proposal: ExponentialFamily | DefensiveMixture,
    seed: int,
    stage: int,
    chunk: int,
    size: int,
) -> EvalTask:
    """Chunk ``chunk`` (``size`` rows) of ``stage``: its samples, ids and seeds."""
    start = chunk * SAMPLE_CHUNK
    ids = np.arange(start, start + size, dtype=np.int64)
    x = proposal.sample(size, chunk_rng(seed, stage, chunk))
    return EvalTask(stage, chunk, ids, x, sample_seeds(seed, stage, ids))


def _stage_batch(
    problem: RareEventProblem, draw: ChunkDraw, result: EvalResult
) -> StageBatch:
    task = result.task
    proposal = draw.proposal
    log_p0 = problem.base.log_prob(task.x)
    log_q = log_p0 if proposal is problem.base else proposal.log_prob(task.x)
    return StageBatch(
        task.stage,
        task.chunk,
        task.ids,
        task.x,
        result.values,
        result.extras,
        log_p0,
        log_q,
        task.seeds,
        draw,
    )
