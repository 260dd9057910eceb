"""How an estimator's samples are drawn, evaluated, recorded and replayed.

Every call of ``f`` an estimator makes goes through an
:class:`EstimationContext`, which the estimator protocol
(:mod:`avrisk.rare.estimator`) passes to ``step`` and ``finalize``. It holds
what the estimator itself does not decide: the run seed (sample ``i`` of
stage ``s`` depends only on it, ``s`` and ``i``), where ``f`` runs (an
:class:`~avrisk.rare.evaluation.Evaluator`), what happens to each evaluated
chunk (recorded, shown as progress), which chunks an interrupted run already
holds (replayed on resume), how many of a stage's samples may fail, and when
a final stage may end early (:mod:`avrisk.rare.stopping`). So a driver
(:mod:`avrisk.pipeline`) can show progress, checkpoint and resume any
estimator the same way.

Two ways in: :meth:`EstimationContext.stage` draws ``n`` fresh samples of a
proposal, shape (n, D), as one stage (:func:`avrisk.rare.stages.run_stage`);
:meth:`EstimationContext.evaluate` evaluates given points (a splitting
estimator's MCMC moves) as one chunk of a stage, with weight 1.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.evaluation import EvalTask, Evaluator, LocalEvaluator
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.problem import (
    SAMPLE_CHUNK,
    RareEventProblem,
    sample_seeds,
)
from avrisk.rare.stages import (
    BatchCache,
    BatchRecorder,
    StageBatch,
    StageResult,
    StageStop,
    run_stage,
)
from avrisk.rare.stopping import StoppingRule

__all__ = [
    "DEFAULT_MAX_FAILED_SHARE",
    "EstimationContext",
    "TooManyFailuresError",
]

#: Share of a stage's samples that may fail before a run stops (see
#: :mod:`avrisk.rare.evaluation`): failed samples bracket the estimate, and
#: beyond this share the bracket says nothing useful.
DEFAULT_MAX_FAILED_SHARE = 0.01


class TooManyFailuresError(RuntimeError):
    """More of a stage's samples failed to evaluate than the run allows."""


class EstimationContext(NamedTuple):
    """How an estimator's samples are evaluated, recorded and replayed.

    Attributes
    ----------
    seed : int
        Run seed: sample ``i`` of stage ``s`` depends only on it, ``s``, ``i``.
    evaluator : Evaluator or None
        Where ``f`` runs (default: this process, chunk after chunk).
    on_batch : callable or None
        Called with each newly evaluated chunk (a samples table, progress).
    cache : callable or None
        Recorded chunks of an interrupted run (resume).
    max_failed_share : float
        Largest share of a stage's samples that may fail to evaluate.
    stopping : StoppingRule or None
        When to end a final stage early (:mod:`avrisk.rare.stopping`).
    """

    seed: int = 0
    evaluator: Evaluator | None = None
    on_batch: BatchRecorder | None = None
    cache: BatchCache | None = None
    max_failed_share: float = DEFAULT_MAX_FAILED_SHARE
    stopping: StoppingRule | None = None

    def stage(
        self,
        problem: RareEventProblem,
        proposal: ExponentialFamily | DefensiveMixture,
        n: int,
        stage: int,
        *,
        keep_stats: bool = False,
        final_after: int | None = None,
    ) -> StageResult:
        """``n`` fresh samples of ``proposal`` as stage ``stage``, evaluated.

        ``final_after``: this is the estimator's final stage, after that many
        calls of ``f``: the stopping rule may end it early (``stopped_by``).

        Raises
        ------
        TooManyFailuresError
            If more than ``max_failed_share`` of them failed (they are
            recorded; a resumed run evaluates them again).
        """
        result = run_stage(
            problem,
            proposal,
            n,
            seed=self.seed,
            stage=stage,
            keep_stats=keep_stats,
            on_batch=self.on_batch,
            cache=self.cache,
            evaluator=self.evaluator,
            stop=None if final_after is None else self._stop(problem, final_after),
        )
        self._check_failures(result.failed, stage)
        return result

    def _stop(self, problem: RareEventProblem, calls_before: int) -> StageStop | None:
        rule = self.stopping
        if rule is None:
            return None

        def stop(done: list[StageBatch], next_size: int) -> str | None:
            values = np.concatenate([b.values for b in done])
            log_w = np.concatenate([b.log_p0 - b.log_q for b in done])
            return rule.reason(values, log_w, problem.gamma, calls_before, next_size)

        return stop

    def evaluate(
        self, problem: RareEventProblem, x: FloatArray, stage: int, chunk: int
    ) -> tuple[FloatArray, np.ndarray]:
        """``f`` at given points (e.g. MCMC proposals) as chunk ``chunk`` of ``stage``.

        At most :data:`~avrisk.rare.problem.SAMPLE_CHUNK` points; their sample
        ids (and so their seeds) are those of chunk ``chunk`` of the stage.

        For estimators whose samples are not fresh draws of one distribution.
        The points are recorded like any chunk (their weight is 1: ``log q =
        log p0``) and replayed on resume when the record holds the same points;
        the caller derives them from its state and the run seed, so a rerun
        asks for the same points again.

        Returns
        -------
        values : ndarray of shape (m,)
        failed : ndarray of bool, shape (m,)
        """
        if len(x) > SAMPLE_CHUNK:
            raise ValueError(
                f"evaluate takes at most {SAMPLE_CHUNK} points per chunk; got {len(x)}"
            )
        cached = self.cache(stage, chunk) if self.cache is not None else None
        if (
            cached is not None
            and cached.x.shape == x.shape
            and np.array_equal(cached.x, x)
            and not cached.failed.any()
        ):
            return cached.values, cached.failed
        ids = chunk * SAMPLE_CHUNK + np.arange(len(x), dtype=np.int64)
        task = EvalTask(stage, chunk, ids, x, sample_seeds(self.seed, stage, ids))
        evaluator = self.evaluator or LocalEvaluator()
        (result,) = evaluator.evaluate(problem, [task])
        log_p0 = problem.base.log_prob(x)
        batch = StageBatch(
            stage,
            chunk,
            ids,
            x,
            result.values,
            result.extras,
            log_p0,
            log_p0,
            task.seeds,
        )
        if self.on_batch is not None:
            self.on_batch(batch)
        self._check_failures(batch.failed, stage)
        return batch.values, batch.failed

    def _check_failures(self, failed: np.ndarray, stage: int) -> None:
        n_failed = int(np.count_nonzero(failed))
        if n_failed > self.max_failed_share * failed.size:
            raise TooManyFailuresError(
                f"{n_failed} of {failed.size} samples of stage {stage} failed to "
                f"evaluate (more than {self.max_failed_share:.1%}); they are "
                "recorded and evaluated again when the run resumes: fix what makes "
                "f fail (see the 'status' column of the samples), then rerun"
            )
