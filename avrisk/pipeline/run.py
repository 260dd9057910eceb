"""Run an estimator into a run directory: progress, checkpoints, resume, summary.

This driver is where mutation lives (files, clocks, progress); the estimators in
:mod:`avrisk.rare` stay pure. It is written against a base distribution and a
batched function, so it serves the simulator (through
:mod:`avrisk.pipeline.objective`) and any other black box alike.
"""

from __future__ import annotations

import platform
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from avrisk.pipeline.lock import run_lock
from avrisk.pipeline.manifest import RecordIntegrityWarning
from avrisk.pipeline.mechanisms import decompose
from avrisk.pipeline.regenerate import chunk_meta
from avrisk.pipeline.repeatability import ReplayCheck, check_repeatable
from avrisk.pipeline.sizing import marginal_row_bytes
from avrisk.pipeline.store import RunDirectory
from avrisk.rare import (
    Estimate,
    EstimationContext,
    Estimator,
    ExponentialFamily,
    RareEventProblem,
    StageBatch,
    estimator_names,
    get_estimator,
    run_estimator,
)
from avrisk.rare.estimator import DEFAULT_METHOD, planned_budget
from avrisk.rare.evaluation import EvalResult, EvalTask, Evaluator, LocalEvaluator
from avrisk.rare.problem import threshold_list
from avrisk.rare.stopping import StoppingRule
from avrisk.version import __version__


class RunSettings:
    """Options of one estimation run: the event, the seed and the estimator's own.

    Parameters
    ----------
    method : str, default=DEFAULT_METHOD
        A registered estimator (:func:`avrisk.rare.estimator_names`):
        ``"splitting_is"`` (the default, :data:`avrisk.rare.estimator.DEFAULT_METHOD`),
        ``"ce"`` (the paper's cross-entropy), ``"naive"``, ``"defensive"`` ...
    gamma : float, default=0.14
        Threshold of the event ``f <= gamma`` [unit of f, s for TTC].
    gamma_test : sequence of float, default=()
        Further thresholds estimated from the final samples.
    seed : int, default=0
        Run seed.
    batch_size : int or None, default=None
        Largest number of rollouts per call of ``f``.
    rel_half_width, max_rollouts, max_seconds : float, int, float or None
        Stopping rules for the final stage (:mod:`avrisk.rare.stopping`);
        the first two define the result and are recorded, a wall-time limit
        is not.
    **options
        The estimator's settings by name (e.g. ``rho``, ``n_iter``,
        ``n_final`` for CE), validated by its settings model.

    Raises
    ------
    ValueError
        For an unknown method or a bad setting (the message names it).

    Examples
    --------
    >>> s = RunSettings("naive", gamma=0.1, n_final=1000)
    >>> s.estimator.budget(), s.to_dict()["n_final"]
    (1000, 1000)
    """

    def __init__(
        self,
        method: str = DEFAULT_METHOD,
        *,
        gamma: float = 0.14,
        gamma_test: Any = (),
        seed: int = 0,
        batch_size: int | None = None,
        rel_half_width: float | None = None,
        max_rollouts: int | None = None,
        max_seconds: float | None = None,
        **options: Any,
    ) -> None:
        if method not in estimator_names():
            raise ValueError(
                f"method must be one of {estimator_names()}; got {method!r}"
            )
        self.method = method
        self.gamma = float(gamma)
        self.gamma_test = tuple(float(g) for g in threshold_list(gamma_test))
        for name, value in (("gamma", self.gamma), ("gamma_test", self.gamma_test)):
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be finite numbers; got {value}")
        self.seed = seed
        self.batch_size = batch_size
        self.estimator: Estimator[Any, Any] = get_estimator(method, **options)
        self.stops = {"rel_half_width": rel_half_width, "max_rollouts": max_rollouts}
        self.max_seconds = max_seconds
        self.stopping_rule()  # validates

    def stopping_rule(self) -> StoppingRule | None:
        """The run's stopping rule (its clock starts now), or None."""
        if not any(v is not None for v in (*self.stops.values(), self.max_seconds)):
            return None
        return StoppingRule(**self.stops, max_seconds=self.max_seconds)

    @property
    def total_rollouts(self) -> int:
        """Calls of ``f`` the run plans to make, before it adapts its budget.

        An estimator that may grow its budget as the event turns out harder
        (subset simulation's regrown replicates) says what it plans without
        growing by ``planned_budget()``; :attr:`most_rollouts` is the bound.
        """
        return planned_budget(self.estimator)

    @property
    def most_rollouts(self) -> int:
        """Calls of ``f`` the run may make at most, growth included."""
        return self.estimator.budget()

    @property
    def rollouts_not_redrawn(self) -> int:
        """Those of them stored in full (:meth:`Estimator.budget_not_redrawn`)."""
        return self.estimator.budget_not_redrawn()

    def to_dict(self) -> dict[str, Any]:
        """The settings that define the run (recorded in config.json)."""
        return {
            "method": self.method,
            "gamma": self.gamma,
            "gamma_test": self.gamma_test,
            **self.estimator.settings.recorded(),
            "seed": self.seed,
            "batch_size": self.batch_size,
            **{k: v for k, v in self.stops.items() if v is not None},
        }

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RunSettings) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        return f"RunSettings({self.to_dict()})"


class RunMonitor(Protocol):
    """What a progress display implements (the CLI's is Rich)."""

    def start(self, total: int, description: str) -> None:
        """The run begins; ``total`` rollouts in all."""

    def advance(self, n: int, *, replayed: bool) -> None:
        """``n`` more rollouts are done (``replayed``: from an earlier session)."""

    def status(self, text: str) -> None:
        """The estimator finished a step (a CE iteration): its status line."""

    def disk(self, row_bytes: float, *, full: bool) -> None:
        """Disk a rollout takes in the samples [B], measured once per session.

        On the first chunk of two or more rows that this session writes
        (:func:`~avrisk.pipeline.sizing.marginal_row_bytes`), before its
        :meth:`advance`; ``full``: whether that chunk stored every column
        (its points are not drawn again from a recorded proposal).
        """


class SilentMonitor:
    """A monitor that shows nothing."""

    def start(self, total: int, description: str) -> None:  # noqa: D102
        pass

    def advance(self, n: int, *, replayed: bool) -> None:  # noqa: D102
        pass

    def status(self, text: str) -> None:  # noqa: D102
        pass

    def disk(self, row_bytes: float, *, full: bool) -> None:  # noqa: D102
        pass


@dataclass
class _Clock:
    """Wall time spent evaluating ``f`` and rollouts evaluated in this session."""

    seconds: float = 0.0
    rollouts: int = 0


def run_estimation(
    run_dir: RunDirectory,
    base: ExponentialFamily,
    f: Callable[..., Any],
    settings: RunSettings,
    *,
    context: dict[str, Any] | None = None,
    monitor: RunMonitor | None = None,
    evaluator: Evaluator | None = None,
    provenance: dict[str, Any] | None = None,
    mechanisms: tuple[str, Mapping[int, str]] | None = None,
    replay_check: ReplayCheck | None = None,
) -> dict[str, Any]:
    """Run (or resume, or just read back) one estimation into ``run_dir``.

    Parameters
    ----------
    run_dir : RunDirectory
        Output directory; a complete run is read back, a partial one resumed.
        A complete run with rollouts that failed to evaluate is reopened and
        those rollouts evaluated again (the rest is replayed).
    base : ExponentialFamily
        ``P0``.
    f : callable
        Batched black box (see :class:`avrisk.rare.RareEventProblem`).
    settings : RunSettings
    context : dict, optional
        Whatever else defines the run (the resolved scenario): recorded in
        config.json and compared on resume.
    monitor : RunMonitor, optional
        Progress display.
    evaluator : Evaluator, optional
        Where ``f`` runs (:mod:`avrisk.rare.evaluation`); default this process.
        Worker processes (:mod:`avrisk.rare.parallel`) build their own ``f``:
        this one is then not called. The summary's ``timing`` counts the time
        the run waits for results, on any evaluator.
    provenance : dict, optional
        The run's provenance stamp (:mod:`avrisk.pipeline.provenance`),
        recorded in the summary.
    mechanisms : (str, mapping of int to str), optional
        An integer output column of ``f`` and the names of its codes: ``p`` is
        decomposed by it (:mod:`avrisk.pipeline.mechanisms`) in the summary's
        ``mechanisms``, for estimators whose estimate is a final-stage mean.
    replay_check : ReplayCheck, optional
        ``f`` without side effects (no trace recording), replayed before the
        run goes on: at a resume, on rows recorded by the earlier sessions (a
        ``f`` that changed since stops the run); before a new run of a ``f``
        that may not be repeatable, on fresh draws evaluated twice
        (:func:`~avrisk.pipeline.repeatability.check_repeatable`). None: no
        check.

    Returns
    -------
    dict
        The summary written to ``summary.json``.

    Raises
    ------
    RunDirectoryError
        If another process is running in ``run_dir`` (:func:`run_lock`), or it
        holds a different run.
    """
    created = not run_dir.path.exists()
    run_dir.refuse_foreign()  # before the lock: a user's folder is left as it was
    with run_lock(run_dir.path):
        try:
            monitor = monitor or SilentMonitor()
            run_dir.claim({"settings": settings.to_dict(), **(context or {})})
            if _read_back(run_dir):
                return run_dir.summary()
            clock = _Clock()
            start = time.perf_counter()
            # the plan, and the check by rays a search takes where X is small
            total = planned_budget(settings.estimator, base.dim)
            monitor.start(total, settings.estimator.describe())
            if replay_check is not None:
                check_repeatable(run_dir, base, replay_check, settings.seed)
            timed = _TimedEvaluator(evaluator or LocalEvaluator(), clock)
            estimate = _estimate(run_dir, base, f, settings, monitor, timed)
            summary = _summary(estimate, settings, clock, time.perf_counter() - start)
            if provenance is not None:
                summary["provenance"] = provenance
            if mechanisms is not None and getattr(
                settings.estimator, "decomposable", False
            ):
                summary["mechanisms"] = _mechanisms(run_dir, settings, *mechanisms)
            run_dir.finish(summary)
            return run_dir.summary()
        except BaseException:
            # Nothing worth keeping (even a failure to write config.json, a full
            # disk): leave no half-made directory that the next run would refuse.
            if created and not run_dir.has_recorded_chunks():
                run_dir.discard()
            raise


def _read_back(run_dir: RunDirectory) -> bool:
    """Whether ``run_dir`` holds a complete run to read back as it is.

    A complete run whose summary or table changed is recomputed (with a
    warning), one with rollouts that failed to evaluate is reopened: both are
    run again (what was recorded is replayed).
    """
    if not run_dir.is_complete:
        return False
    problem = run_dir.record_problem()
    if problem is not None:  # a changed summary or table: never printed
        warnings.warn(f"{problem}: recomputing", RecordIntegrityWarning, stacklevel=3)
        run_dir.recompute()
        return False
    if not run_dir.has_failed_samples():
        return True
    run_dir.reopen()
    return False


def _estimate(
    run_dir: RunDirectory,
    base: ExponentialFamily,
    f: Callable[..., Any],
    s: RunSettings,
    monitor: RunMonitor,
    evaluator: Evaluator,
) -> Estimate:
    measured = False

    def on_batch(batch: StageBatch) -> None:
        nonlocal measured
        table = run_dir.chunks.record(batch)
        if not measured:
            row_bytes = marginal_row_bytes(table)
            if row_bytes is not None:
                measured = True
                monitor.disk(row_bytes, full=chunk_meta(table.schema) is None)
        monitor.advance(len(batch.values), replayed=False)

    def cache(stage: int, chunk: int) -> StageBatch | None:
        """A recorded chunk to replay; None for one with failed rollouts.

        Such a chunk is evaluated again (:func:`~avrisk.rare.stages.run_stage`):
        it is counted once, as simulated, not also as replayed.
        """
        batch = run_dir.chunks.cached(stage, chunk)
        if batch is None or batch.failed.any():
            return None
        monitor.advance(len(batch.values), replayed=True)
        return batch

    infos: list[Any] = []
    estimator = s.estimator

    def on_step(info: Any, state: Any) -> None:
        infos.append(info)
        run_dir.checkpoint(estimator.checkpoint(state, infos))
        monitor.status(estimator.progress(info))

    problem = RareEventProblem(base, f, s.gamma, s.gamma_test, s.batch_size)
    context = EstimationContext(
        s.seed, evaluator, on_batch, cache, stopping=s.stopping_rule()
    )
    return run_estimator(estimator, problem, context, callback=on_step)


def _mechanisms(
    run_dir: RunDirectory,
    settings: RunSettings,
    column: str,
    names: Mapping[int, str],
) -> dict[str, Any]:
    """``p`` by the codes of ``column``, from the final stage's chunks."""
    table = run_dir.chunks.final_stage(["f", "weight", "status", column])

    def floats(name: str) -> np.ndarray:  # nulls (older chunks) become NaN
        return np.asarray(table[name].to_numpy(zero_copy_only=False), dtype=float)

    labels = np.nan_to_num(floats(column), nan=-1).astype(np.int64)
    return {
        "column": column,
        "by_gamma": decompose(
            table["f"].to_numpy(),
            table["weight"].to_numpy(),
            labels,
            names,
            (settings.gamma, *settings.gamma_test),
            weighted=settings.estimator.weighted,
            failed=np.nan_to_num(floats("status")) != 0,
        ),
    }


class _TimedEvaluator:
    """An evaluator's results, timed and counted into ``clock``.

    The time is what the run waits for results (in this process or from
    workers), so rollouts per second is the run's throughput on any backend.
    """

    def __init__(self, inner: Evaluator, clock: _Clock) -> None:
        self.inner = inner
        self.clock = clock

    def evaluate(
        self, problem: RareEventProblem, tasks: Iterable[EvalTask]
    ) -> Iterator[EvalResult]:
        """The inner evaluator's results, one by one."""
        results = iter(self.inner.evaluate(problem, tasks))
        try:
            while True:
                t0 = time.perf_counter()
                result = next(results, None)
                self.clock.seconds += time.perf_counter() - t0
                if result is None:
                    return
                self.clock.rollouts += len(result.values)
                yield result
        finally:
            close = getattr(results, "close", None)
            if close is not None:
                close()


def _summary(
    estimate: Estimate, settings: RunSettings, clock: _Clock, wall: float
) -> dict[str, Any]:
    import scipy
    import torch

    return {
        "method": settings.method,
        "settings": settings.to_dict(),
        "estimate": estimate.to_dict(),
        "timing": {
            "wall_time_s": wall,
            "rollouts_evaluated": clock.rollouts,
            "rollouts_replayed": estimate.n_evals - clock.rollouts,
            "seconds_in_f": clock.seconds,
            "rollouts_per_second": clock.rollouts / clock.seconds
            if clock.seconds
            else None,
        },
        "versions": {
            "avrisk": __version__,
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "torch": torch.__version__,
        },
    }
