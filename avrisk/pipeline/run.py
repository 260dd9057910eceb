"""Run an estimator into a run directory: progress, checkpoints, resume, summary.

This driver is where mutation lives (files, clocks, progress); the estimators in
:mod:`avrisk.rare` stay pure. It is written against a base distribution and a
batched function, so it serves the simulator (through
:mod:`avrisk.pipeline.objective`) and any other black box alike.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

import avrisk
from avrisk.pipeline.store import RunDirectory
from avrisk.rare import (
    CEInfo,
    CEState,
    Estimate,
    ExponentialFamily,
    StageBatch,
    cross_entropy,
    naive_mc,
)
from avrisk.rare.cross_entropy import check_ce_settings
from avrisk.rare.defensive import check_defensive

Method = Literal["naive", "ce"]

#: Settings that only a cross-entropy run uses.
CE_ONLY_SETTINGS = ("rho", "alpha", "n_per_iter", "n_iter", "select", "defensive")


@dataclass(frozen=True)
class RunSettings:
    """Options of one estimation run (the paper's names and defaults).

    Attributes
    ----------
    method : {"naive", "ce"}
        Naive Monte Carlo or cross-entropy importance sampling.
    gamma : float
        Threshold of the event ``f <= gamma`` [unit of f, s for TTC].
    gamma_test : tuple of float
        Further thresholds estimated from the final samples.
    rho, alpha : float
        CE quantile level and smoothing.
    n_per_iter, n_iter : int
        CE search: samples per iteration and iterations.
    n_final : int
        Samples of the final stage (all samples, for naive MC).
    seed : int
        Run seed.
    batch_size : int or None
        Largest number of rollouts per call of ``f``.
    select : str
        CE rule choosing the final proposal (``"quantile"``: the paper's).
    defensive : float
        Share of CE's final stage drawn from the base distribution (a
        defensive mixture, :mod:`avrisk.rare.defensive`); 0: the paper's.
    """

    method: Method = "ce"
    gamma: float = 0.14
    gamma_test: tuple[float, ...] = ()
    rho: float = 0.01
    alpha: float = 0.8
    n_per_iter: int = 5000
    n_iter: int = 100
    n_final: int = 100_000
    seed: int = 0
    batch_size: int | None = None
    select: str = "quantile"
    defensive: float = 0.0

    def __post_init__(self) -> None:
        if self.method not in ("naive", "ce"):
            raise ValueError(f"method must be 'naive' or 'ce'; got {self.method!r}")
        check_ce_settings(self.rho, self.alpha, self.select)
        check_defensive(self.defensive)
        for name in ("n_per_iter", "n_final"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1; got {getattr(self, name)}")
        if self.n_iter < 0:
            raise ValueError(f"n_iter must be >= 0; got {self.n_iter}")
        object.__setattr__(self, "gamma_test", tuple(float(g) for g in self.gamma_test))

    @property
    def total_rollouts(self) -> int:
        """Calls of ``f`` the run makes in all."""
        if self.method == "naive":
            return self.n_final
        return self.n_iter * self.n_per_iter + self.n_final

    def to_dict(self) -> dict[str, Any]:
        """The settings that define the run (recorded in config.json)."""
        out = asdict(self)
        if self.method == "naive":  # CE-only settings do not define a naive run
            for key in CE_ONLY_SETTINGS:
                out.pop(key)
        elif not self.defensive:  # the paper's plain proposal: recorded as before
            out.pop("defensive")
        return out


class RunMonitor(Protocol):
    """What a progress display implements (the CLI's is Rich)."""

    def start(self, total: int, description: str) -> None:
        """The run begins; ``total`` rollouts in all."""

    def advance(self, n: int, *, replayed: bool) -> None:
        """``n`` more rollouts are done (``replayed``: from an earlier session)."""

    def iteration(self, info: CEInfo) -> None:
        """A CE iteration finished."""


class SilentMonitor:
    """A monitor that shows nothing."""

    def start(self, total: int, description: str) -> None:  # noqa: D102
        pass

    def advance(self, n: int, *, replayed: bool) -> None:  # noqa: D102
        pass

    def iteration(self, info: CEInfo) -> None:  # noqa: D102
        pass


@dataclass
class _Clock:
    """Wall time spent inside ``f`` and rollouts evaluated in this session."""

    seconds: float = 0.0
    rollouts: int = 0
    history: list[CEInfo] = field(default_factory=list)


def run_estimation(
    run_dir: RunDirectory,
    base: ExponentialFamily,
    f: Callable[..., Any],
    settings: RunSettings,
    *,
    context: dict[str, Any] | None = None,
    monitor: RunMonitor | None = None,
) -> dict[str, Any]:
    """Run (or resume, or just read back) one estimation into ``run_dir``.

    Parameters
    ----------
    run_dir : RunDirectory
        Output directory; a complete run is read back, a partial one resumed.
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

    Returns
    -------
    dict
        The summary written to ``summary.json``.
    """
    monitor = monitor or SilentMonitor()
    config = {"settings": settings.to_dict(), **(context or {})}
    created = not run_dir.path.exists()
    run_dir.claim(config)
    if run_dir.is_complete:
        return run_dir.summary()
    clock = _Clock()
    start = time.perf_counter()
    monitor.start(settings.total_rollouts, _describe(settings))
    try:
        estimate = _estimate(run_dir, base, _timed(f, clock), settings, monitor, clock)
    except BaseException:
        if created and not run_dir.has_recorded_chunks():
            run_dir.discard()  # nothing worth keeping: leave no half-made directory
        raise
    wall = time.perf_counter() - start
    summary = _summary(estimate, settings, clock, wall)
    run_dir.finish(summary)
    return run_dir.summary()


def _estimate(
    run_dir: RunDirectory,
    base: ExponentialFamily,
    f: Callable[..., Any],
    s: RunSettings,
    monitor: RunMonitor,
    clock: _Clock,
) -> Estimate:
    def on_batch(batch: StageBatch) -> None:
        run_dir.record(batch)
        monitor.advance(len(batch.values), replayed=False)

    def cache(stage: int, chunk: int) -> StageBatch | None:
        batch = run_dir.cached(stage, chunk)
        if batch is not None:
            monitor.advance(len(batch.values), replayed=True)
        return batch

    def on_iteration(info: CEInfo, state: CEState) -> None:
        clock.history.append(info)
        run_dir.checkpoint(info, state, clock.history)
        monitor.iteration(info)

    common = dict(
        seed=s.seed,
        gamma_test=s.gamma_test,
        batch_size=s.batch_size,
        on_batch=on_batch,
        cache=cache,
    )
    if s.method == "naive":
        return naive_mc(f, base, s.gamma, s.n_final, **common)
    return cross_entropy(
        f,
        base,
        s.gamma,
        rho=s.rho,
        alpha=s.alpha,
        n_per_iter=s.n_per_iter,
        n_iter=s.n_iter,
        n_final=s.n_final,
        select=s.select,
        defensive=s.defensive,
        callback=on_iteration,
        **common,
    )


def _timed(f: Callable[..., Any], clock: _Clock) -> Callable[..., Any]:
    """``f`` with its wall time and rows counted (keeps ``needs_seeds``)."""

    def timed(x: np.ndarray, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = f(x, **kwargs)
        clock.seconds += time.perf_counter() - t0
        clock.rollouts += len(x)
        return out

    timed.needs_seeds = getattr(f, "needs_seeds", False)  # type: ignore[attr-defined]
    return timed


def _describe(s: RunSettings) -> str:
    if s.method == "naive":
        return f"naive MC, {s.n_final:,} rollouts"
    return f"CE {s.n_iter}x{s.n_per_iter:,} + {s.n_final:,}"


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
            "avrisk": avrisk.__version__,
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "torch": torch.__version__,
        },
    }
