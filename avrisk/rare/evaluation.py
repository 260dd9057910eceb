"""The evaluator seam: where the calls of ``f`` happen.

The engine cuts every stage into chunks and hands them to an evaluator as
:class:`EvalTask` objects (stage, chunk, sample ids, samples, seeds). The
evaluator returns one :class:`EvalResult` per task, **in any order**: the
engine files each result by its ``(stage, chunk)`` and sample ids, so the
estimate is the same whatever the order, the number of workers or the
machine that did the work. :class:`LocalEvaluator` (the default) evaluates the
tasks one after another in this process; a parallel or remote backend is one
more class with the same :meth:`Evaluator.evaluate` method (a thread pool
takes ten lines: see ``tests/rare/test_evaluation.py``).

Failed samples
--------------
``f`` may return a per-sample ``status`` column (0: evaluated; anything else:
the evaluation of that sample failed, e.g. an external policy timed out). A
failed sample's value may be NaN; it is never dropped silently: the engine
counts it, brackets the estimate (failed samples counted safe / dangerous) and
a resumed run evaluates it again (:mod:`avrisk.rare.stages`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import NamedTuple, Protocol

import numpy as np

from avrisk.rare.families.base import FloatArray
from avrisk.rare.problem import STATUS, RareEventProblem

__all__ = [
    "EvalResult",
    "EvalTask",
    "Evaluator",
    "LocalEvaluator",
    "evaluate_task",
    "failed_mask",
]


class EvalTask(NamedTuple):
    """A chunk of samples to evaluate.

    Attributes
    ----------
    stage : int
        Stage of the run (0: final stage; CE iteration ``k`` is ``k + 1``).
    chunk : int
        Index of the chunk within the stage.
    ids : ndarray of int64, shape (m,)
        Sample ids within the stage.
    x : ndarray of float64, shape (m, D)
        The samples.
    seeds : ndarray of int64, shape (m,)
        One seed per sample, for a stochastic ``f``.
    """

    stage: int
    chunk: int
    ids: np.ndarray
    x: FloatArray
    seeds: np.ndarray


class EvalResult(NamedTuple):
    """What ``f`` gave for one task.

    Attributes
    ----------
    task : EvalTask
    values : ndarray of float64, shape (m,)
        ``f`` of every sample (NaN allowed only where ``failed``).
    extras : dict of str to ndarray of shape (m,)
        Other per-sample outputs (event flags, ``status``): recorded, not used.
    """

    task: EvalTask
    values: FloatArray
    extras: dict[str, np.ndarray]

    @property
    def failed(self) -> np.ndarray:
        """Bool (m,): samples whose evaluation failed (``status != 0``)."""
        return failed_mask(self.values, self.extras)


class Evaluator(Protocol):
    """Evaluates chunks of samples of one problem (see module docstring)."""

    def evaluate(
        self, problem: RareEventProblem, tasks: Iterable[EvalTask]
    ) -> Iterator[EvalResult]:
        """One result per task, in any order; may consume ``tasks`` lazily."""
        ...


class LocalEvaluator:
    """Evaluate tasks one after another in this process (the default)."""

    def evaluate(
        self, problem: RareEventProblem, tasks: Iterable[EvalTask]
    ) -> Iterator[EvalResult]:
        """Yield each task's result as soon as it is evaluated."""
        for task in tasks:
            yield evaluate_task(problem, task)


def evaluate_task(problem: RareEventProblem, task: EvalTask) -> EvalResult:
    """``f`` on one task, checked (what every evaluator runs for a task)."""
    values, extras = problem.evaluate(task.x, task.seeds)
    return EvalResult(task, values, extras)


def failed_mask(values: FloatArray, extras: dict[str, np.ndarray]) -> np.ndarray:
    """Bool, shape of ``values``: where the ``status`` output is non-zero."""
    status = extras.get(STATUS)
    if status is None:
        return np.zeros(len(values), dtype=bool)
    return np.asarray(status) != 0
