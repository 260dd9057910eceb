"""Is ``f`` the one a run was recorded with? Rollouts replayed at a start and resume.

Resume, the retry of failed rollouts and the report's replays all assume that
a rollout depends only on its ``X`` and seed, with the same ``f`` in every
session of a run. A run directory's configuration and provenance stamp pin
the scenario and the weights files, not the code behind them: an ego named by
import path may have been edited between two sessions, and an AV process
behind an address restarted with other code. A resumed run whose ``f``
changed would mix the numbers of two experiments without saying so, and
could show the traces of one ego in the report of the other.

So a resume replays, for every ``f`` (in-process egos too), the rows that
:func:`replayed_rows` picks: the first :data:`FIRST_ROWS` that succeeded in
the run's first recorded chunk (typical draws), and the :data:`LOWEST_ROWS`
of lowest ``f`` of every recorded chunk (its hits and near-hits, where a
change in how an ego brakes shows first, and which draws of ``P0`` rarely
reach). They cost one batch of at most ``FIRST_ROWS + LOWEST_ROWS``
rollouts, evaluated in this process. ``f`` and every integer output (crash
flags, contact) must match the record: ``f`` within the check's tolerance
(none on the CPU, whose rollouts do not depend on the batch they are
simulated in), the others exactly. Rows recorded as failed (an AV that was
down) are never picked; where no recorded row succeeded, nothing of the
earlier sessions is reused (every chunk with a failed rollout is evaluated
again) and nothing can be compared: a :class:`UncheckedResumeWarning` says
so and the run goes on, checked as a new one. Refusing there would block the
ordinary recovery (start the AV, rerun the command) without protecting any
number. A replay whose rollouts all fail now stops the run: the ``f`` it would
go on with cannot be checked.

Where ``f`` may not be repeatable at all (an external AV, an actor with
``deterministic = False``, :mod:`avrisk.sim.interfaces`), a new run first
evaluates :data:`REPLAYED` fresh draws of ``P0`` twice, in reverse order the
second time. Any difference stops the run (:class:`NotRepeatableError`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from avrisk.pipeline.store import RunDirectory
from avrisk.rare import ExponentialFamily, StageBatch
from avrisk.rare.problem import STATUS

__all__ = [
    "FIRST_ROWS",
    "LOWEST_ROWS",
    "REPLAYED",
    "NotRepeatableError",
    "ReplayCheck",
    "UncheckedResumeWarning",
    "check_repeatable",
    "replayed_rows",
]

#: Fresh draws evaluated twice before a new run of a ``f`` that may not repeat.
REPLAYED = 4
#: Rows of the first recorded chunk replayed at a resume (typical draws).
FIRST_ROWS = 4
#: Recorded rows of lowest ``f`` replayed at a resume (hits and near-hits).
LOWEST_ROWS = 4


class NotRepeatableError(RuntimeError):
    """``f`` gave two results for one ``(X, seed)`` (the message shows them)."""


class UncheckedResumeWarning(UserWarning):
    """A resume found no recorded rollout that succeeded: nothing to compare."""


@dataclass(frozen=True)
class ReplayCheck:
    """How a run checks ``f`` against its record (see the module docstring).

    Attributes
    ----------
    f : callable
        The batched black box, with no side effects worth keeping (not one
        that records traces).
    fresh : bool, default=False
        Whether ``f`` may not be repeatable (an external AV): a new run then
        first evaluates fresh draws twice.
    tolerance : float, default=0.0
        Largest ``|f now - f recorded|`` accepted [unit of f]: the rounding
        of a device whose results depend on the batch's size (0: exact).
    """

    f: Callable[..., Any]
    fresh: bool = False
    tolerance: float = 0.0


def check_repeatable(
    run_dir: RunDirectory, base: ExponentialFamily, check: ReplayCheck, seed: int
) -> None:
    """Replay rollouts of ``check.f`` and compare (see the module docstring).

    Parameters
    ----------
    run_dir : RunDirectory
        Its recorded chunks, if any, are the reference.
    base : ExponentialFamily
        ``P0``, for fresh draws.
    check : ReplayCheck
    seed : int
        Run seed (the fresh draws depend only on it).

    Raises
    ------
    NotRepeatableError
        If a rollout replayed gave another result than recorded, or than
        its first evaluation; or if every replay of a resume failed.

    Warns
    -----
    UncheckedResumeWarning
        At a resume where no recorded rollout succeeded.
    """
    if run_dir.has_recorded_chunks():
        rows = replayed_rows(run_dir)
        if rows:
            _compare_with_record(run_dir, rows, check)
            return
        warnings.warn(
            f"no rollout recorded in {run_dir.path} succeeded: nothing of the earlier "
            "session is reused, and the ego it ran with cannot be compared",
            UncheckedResumeWarning,
            stacklevel=3,
        )
    if check.fresh:
        _evaluate_twice(base, check.f, seed)


def replayed_rows(run_dir: RunDirectory) -> list[tuple[StageBatch, int]]:
    """The recorded rows a resume replays, as ``(chunk, row)``; none if none succeeded.

    The first :data:`FIRST_ROWS` rows that succeeded, in the order the run
    evaluated its chunks (the first chunk's, unless all of them failed), and
    the :data:`LOWEST_ROWS` others of lowest ``f`` among all that succeeded.
    Only the chunks holding them are read in full (and verified); one that
    does not verify is removed (the run evaluates it again) and the rows are
    picked again from the others.
    """
    outcomes = run_dir.chunks.recorded_outcomes()
    if not outcomes:
        return []
    ok = np.concatenate([~failed for *_, failed in outcomes])
    which = np.repeat(np.arange(len(outcomes)), [len(o[2]) for o in outcomes])[ok]
    rows = np.concatenate([np.arange(len(o[2])) for o in outcomes])[ok]
    f = np.concatenate([o[2] for o in outcomes])[ok]
    rest = f[FIRST_ROWS:]
    lowest = (
        np.argpartition(rest, LOWEST_ROWS)[:LOWEST_ROWS]
        if len(rest) > LOWEST_ROWS
        else np.arange(len(rest))
    )
    picked = np.concatenate(
        [
            np.arange(min(FIRST_ROWS, len(f))),
            FIRST_ROWS + lowest[np.argsort(rest[lowest], kind="stable")],
        ]
    )
    keys = [outcomes[w][:2] for w in which[picked]]
    read = {key: run_dir.chunks.cached(*key) for key in sorted(set(keys))}
    chunks = {key: batch for key, batch in read.items() if batch is not None}
    if len(chunks) < len(read):  # cached removed one that did not verify
        return replayed_rows(run_dir)
    return [
        (chunks[key], int(row)) for key, row in zip(keys, rows[picked], strict=True)
    ]


def _compare_with_record(
    run_dir: RunDirectory, rows: list[tuple[StageBatch, int]], check: ReplayCheck
) -> None:
    """Replay ``rows`` in one batch; raise on the first that differs."""
    x = np.stack([batch.x[row] for batch, row in rows])
    seeds = np.array([batch.seeds[row] for batch, row in rows], dtype=np.int64)
    out = _outputs(check.f, x, seeds)
    ok = np.asarray(out.get(STATUS, np.zeros(len(x))), dtype=float) == 0
    if not ok.any():
        raise NotRepeatableError(
            f"the {len(x)} rollouts replayed to check the ego against the run "
            f"recorded in {run_dir.path} all failed now: start the ego (or fix "
            "it) and rerun the command"
        )
    for i in np.flatnonzero(ok):
        batch, row = rows[i]
        recorded = {"f": batch.values, **batch.extras}
        for name, now in out.items():
            if name == STATUS or name not in recorded:
                continue
            was, now_i = recorded[name][row], np.asarray(now)[i]
            if not _same(was, now_i, check.tolerance):
                raise NotRepeatableError(
                    f"f differs from the run recorded in {run_dir.path}: the rollout "
                    f"of stage {batch.stage}, chunk {batch.chunk}, row {row} (seed "
                    f"{int(batch.seeds[row])}) gives {name} = {now_i.item()!r} "
                    f"now, {was.item()!r} recorded; the ego (or other code) changed "
                    "since, or does not repeat its rollouts: resume with the ego the "
                    "run was recorded with, or run into another output directory"
                )


def _same(recorded: Any, now: Any, tolerance: float) -> bool:
    """Whether an output matches its record: a float within ``tolerance``.

    An integer or flag must be equal; anything else (a text, a value not
    recorded by an older avrisk) is not compared.
    """
    if isinstance(recorded, (float, np.floating)):
        return bool(np.isnan(recorded) or abs(float(now) - recorded) <= tolerance)
    if isinstance(recorded, (int, np.integer, np.bool_)):
        return bool(now == recorded)
    return True


def _evaluate_twice(base: ExponentialFamily, f: Callable[..., Any], seed: int) -> None:
    """Evaluate :data:`REPLAYED` fresh draws twice; raise if they differ."""
    rng = np.random.default_rng([seed, 0xC4EC])
    x = base.sample(REPLAYED, rng)
    seeds = rng.integers(0, 2**62, REPLAYED, dtype=np.int64)
    first = _outputs(f, x, seeds)
    again = {
        k: np.asarray(v)[::-1] for k, v in _outputs(f, x[::-1], seeds[::-1]).items()
    }
    both = _ok(first) & _ok(again)
    differ = np.flatnonzero(both & (first["f"] != again["f"]))
    if differ.size:
        i = differ[0]
        raise NotRepeatableError(
            f"f is not repeatable: {differ.size} of {int(both.sum())} rollouts "
            f"replayed with the same X and seed gave other results than those "
            f"evaluated just before (seed {int(seeds[i])}: f = {first['f'][i]!r}, "
            f"then {again['f'][i]!r}). The estimate, resume and retries assume "
            "that a rollout depends only on X and its seed; an external AV must "
            "draw any randomness from the seeds of its reset message "
            "(docs/ego-protocol.md)"
        )


def _outputs(
    f: Callable[..., Any], x: np.ndarray, seeds: np.ndarray
) -> dict[str, np.ndarray]:
    """The outputs of ``f`` on ``x``, as a dict with ``f``."""
    out = f(x, seeds=seeds) if getattr(f, "needs_seeds", False) else f(x)
    if not isinstance(out, Mapping):
        return {"f": np.asarray(out, dtype=np.float64)}
    return {**out, "f": np.asarray(out["f"], dtype=np.float64)}


def _ok(out: Mapping[str, np.ndarray]) -> np.ndarray:
    """Rollouts evaluated (status 0)."""
    status = out.get(STATUS)
    return np.ones(len(out["f"]), dtype=bool) if status is None else status == 0
