"""Is ``f`` repeatable? A few rollouts replayed at a run's start and at resume.

Resume, the retry of failed rollouts and the report's replays all assume that
a rollout depends only on its ``X`` and seed. That holds for the simulator
and its in-process actors, whose runs are not checked; an external AV may
break it (a stack that draws from an unseeded generator), and so may an
actor that says so (``deterministic = False``, :mod:`avrisk.sim.interfaces`):
their runs are (the caller passes ``replay_check`` to
:func:`~avrisk.pipeline.run.run_estimation`).
:func:`check_repeatable` replays :data:`REPLAYED` rollouts: at resume, rows of
a recorded chunk (evaluated by an earlier session, maybe by an AV process
since restarted); at the start, fresh draws of ``P0`` evaluated twice, in
reverse order the second time. Any difference stops the run
(:class:`NotRepeatableError`): a run directory whose chunks cannot be
reproduced would mix numbers of different experiments without saying so.
Rollouts that fail to evaluate are left out of the comparison (they are
the engine's to count and retry).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from avrisk.pipeline.store import RunDirectory
from avrisk.rare import ExponentialFamily
from avrisk.rare.problem import STATUS

__all__ = ["REPLAYED", "NotRepeatableError", "check_repeatable"]

#: Rollouts replayed by the check.
REPLAYED = 4


class NotRepeatableError(RuntimeError):
    """``f`` gave two results for one ``(X, seed)`` (the message shows them)."""


def check_repeatable(
    run_dir: RunDirectory,
    base: ExponentialFamily,
    f: Callable[..., Any],
    seed: int,
    n: int = REPLAYED,
) -> None:
    """Replay ``n`` rollouts of ``f`` and compare (see the module docstring).

    Parameters
    ----------
    run_dir : RunDirectory
        Its recorded chunks, if any, are the reference.
    base : ExponentialFamily
        ``P0``, for fresh draws.
    f : callable
        The batched black box, with no side effects worth keeping (not one
        that records traces).
    seed : int
        Run seed (the fresh draws depend only on it).
    n : int, default=REPLAYED

    Raises
    ------
    NotRepeatableError
        If a rollout evaluated twice gave two values of ``f``.
    """
    recorded = next(
        (b for b in (run_dir.cached(s, 0) for s in (1, 0)) if b is not None), None
    )
    if recorded is not None:
        ok = np.flatnonzero(~recorded.failed)[:n]
        x, seeds = recorded.x[ok], recorded.seeds[ok]
        first, first_ok = recorded.values[ok], np.ones(len(ok), dtype=bool)
        where = f"recorded in {run_dir.path} by an earlier session"
    else:
        rng = np.random.default_rng([seed, 0xC4EC])
        x, seeds = base.sample(n, rng), rng.integers(0, 2**62, n, dtype=np.int64)
        first, first_ok = _evaluate(f, x, seeds)
        where = "evaluated just before"
    if len(x) == 0:
        return
    again, again_ok = (a[::-1] for a in _evaluate(f, x[::-1], seeds[::-1]))
    both = first_ok & again_ok
    differ = np.flatnonzero(both & (first != again))
    if differ.size:
        i = differ[0]
        raise NotRepeatableError(
            f"f is not repeatable: {differ.size} of {int(both.sum())} rollouts "
            f"replayed with the same X and seed gave other results than those "
            f"{where} (seed {int(seeds[i])}: f = {first[i]!r}, then {again[i]!r}). "
            "The estimate, resume and retries assume that a rollout depends only "
            "on X and its seed; an external AV must draw any randomness from the "
            "seeds of its reset message (docs/ego-protocol.md)"
        )


def _evaluate(
    f: Callable[..., Any], x: np.ndarray, seeds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``f`` (n,) and whether each was evaluated (status 0)."""
    out = f(x, seeds=seeds) if getattr(f, "needs_seeds", False) else f(x)
    if not isinstance(out, Mapping):
        return np.asarray(out, dtype=np.float64), np.ones(len(x), dtype=bool)
    status = out.get(STATUS)
    ok = np.ones(len(x), dtype=bool) if status is None else np.asarray(status) == 0
    return np.asarray(out["f"], dtype=np.float64), ok
