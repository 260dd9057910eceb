"""The rare-event problem: a base distribution, a black-box ``f`` and a threshold.

The event of interest is ``{f(X) <= gamma}`` with ``X ~ P0`` (low ``f`` is bad,
as for time-to-collision). ``f`` is a batched black box: it takes a float64
array of shape ``(n, D)`` and returns ``n`` values. A function whose outcome
also depends on per-sample randomness (a stochastic simulator) declares
``needs_seeds = True`` and is then called as ``f(x, seeds=seeds)`` with one
``int64`` seed per row, derived from the run seed, the stage and the sample's
index; so a row's value never depends on how the rows were batched.

Samples of a stage are drawn in chunks of :data:`SAMPLE_CHUNK` rows, chunk ``j``
from its own generator (:func:`chunk_rng`): sample ``i`` of a stage depends only
on the run seed, the stage and ``i``, memory stays bounded for any ``n``, and a
run interrupted between chunks can resume from the chunks it has recorded.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray

BatchFunction = Callable[..., Any]

#: Stage number of the final (estimation) stage; CE search iteration k is k + 1.
FINAL_STAGE = 0

#: Optional per-sample output of ``f``: 0 evaluated, non-zero failed (NaN allowed).
STATUS = "status"

#: Rows drawn from one random generator; fixed, because changing it changes X.
SAMPLE_CHUNK = 8192

_SPLITMIX_GAMMA = np.uint64(0x9E3779B97F4A7C15)


class InvalidOutputError(ValueError):
    """``f`` returned something unusable: the wrong shape, or NaN."""


@dataclass(frozen=True)
class RareEventProblem:
    """``p = P0(f(X) <= gamma)``, checked once at the boundary.

    Parameters
    ----------
    base : ExponentialFamily
        The distribution ``P0`` of ``X``.
    f : callable
        ``f(x) -> (n,)`` for ``x`` of shape (n, D); or ``f(x, seeds=...)`` if it
        has an attribute ``needs_seeds = True``. ``+inf`` is allowed (for
        "never"), ``NaN`` is an error.
    gamma : float
        Threshold of the event.
    gamma_test : sequence of float, default=()
        Further thresholds estimated from the same final samples.
    batch_size : int or None, default=None
        Largest number of rows passed to ``f`` in one call (``None``: all).
    """

    base: ExponentialFamily
    f: BatchFunction
    gamma: float
    gamma_test: tuple[float, ...] = ()
    batch_size: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.base, ExponentialFamily):
            raise TypeError(
                f"base must be an avrisk.rare family (ScaledBeta, FixedCovNormal, "
                f"Product ...); got {type(self.base).__name__}"
            )
        if not callable(self.f):
            raise TypeError(f"f must be callable; got {type(self.f).__name__}")
        if not np.isfinite(self.gamma):
            raise ValueError(f"gamma must be a finite number; got {self.gamma}")
        tests = tuple(float(g) for g in self.gamma_test)
        if not all(np.isfinite(tests)):
            raise ValueError(
                f"gamma_test must hold finite numbers; got {self.gamma_test}"
            )
        object.__setattr__(self, "gamma", float(self.gamma))
        object.__setattr__(self, "gamma_test", tests)
        if self.batch_size is not None and (
            int(self.batch_size) != self.batch_size or self.batch_size < 1
        ):
            raise ValueError(
                f"batch_size must be a positive integer or None; got {self.batch_size}"
            )
        if not self.base.in_search_box():
            raise ValueError("the base distribution lies outside its own CE search box")

    @property
    def thresholds(self) -> tuple[float, ...]:
        """``gamma`` followed by the test thresholds not equal to it, in order."""
        return tuple(dict.fromkeys((self.gamma, *self.gamma_test)))

    def evaluate(
        self, x: FloatArray, seeds: np.ndarray
    ) -> tuple[FloatArray, dict[str, np.ndarray]]:
        """``f`` on every row of ``x`` (shape (n, D)), in batches.

        ``f`` returns either the ``(n,)`` values, or a mapping with the values
        under ``"f"`` and any other per-sample outputs (crash flags, ...) as
        ``(n,)`` arrays: those are passed on for recording. One of them is
        understood: ``"status"``, non-zero where the evaluation of a sample
        failed (its value may then be NaN; see :mod:`avrisk.rare.evaluation`).

        Returns
        -------
        values : ndarray of shape (n,)
        extras : dict of str to ndarray of shape (n,)

        Raises
        ------
        InvalidOutputError
            If ``f`` returns the wrong shape, or NaN for a sample not marked failed.
        """
        return evaluate_batched(self.f, x, seeds, self.batch_size)


def evaluate_batched(
    f: BatchFunction, x: FloatArray, seeds: np.ndarray, batch_size: int | None
) -> tuple[FloatArray, dict[str, np.ndarray]]:
    """``f`` on every row of ``x`` (shape (n, D)), ``batch_size`` rows per call.

    What :meth:`RareEventProblem.evaluate` does, for a worker that holds its
    own ``f`` (:mod:`avrisk.rare.parallel`) and not the problem.
    """
    needs_seeds = bool(getattr(f, "needs_seeds", False))
    step = batch_size or max(1, len(x))
    parts: list[FloatArray] = []
    extras: dict[str, list[np.ndarray]] = {}
    for start in range(0, len(x), step):
        chunk = x[start : start + step]
        if needs_seeds:
            out = f(chunk, seeds=seeds[start : start + step])
        else:
            out = f(chunk)
        if isinstance(out, Mapping):
            for name, column in out.items():
                if name != "f":
                    extras.setdefault(name, []).append(
                        _column(column, len(chunk), name)
                    )
            out = out["f"]
        parts.append(_column(out, len(chunk), "f", dtype=np.float64))
    values = np.concatenate(parts) if parts else np.empty(0)
    columns = {k: np.concatenate(v) for k, v in extras.items()}
    nan = np.isnan(values)
    if STATUS in columns:  # a failed sample may have no value
        nan &= np.asarray(columns[STATUS]) == 0
    bad = np.flatnonzero(nan)
    if bad.size:
        raise InvalidOutputError(
            f"f returned NaN for {bad.size} of {values.size} samples "
            f"(first at row {bad[0]}: x = {x[bad[0]].tolist()[:8]}...); "
            f"a sample whose evaluation failed must say so in a "
            f"{STATUS!r} output (non-zero)"
        )
    return values, columns


def _column(out: Any, n: int, name: str, dtype: Any = None) -> np.ndarray:
    arr = np.asarray(out, dtype=dtype)
    if arr.shape != (n,):
        raise InvalidOutputError(
            f"f must return an array of shape ({n},) for {n} input rows; "
            f"got shape {arr.shape} for output {name!r}"
        )
    return arr


def chunk_rng(seed: int, stage: int, chunk: int) -> np.random.Generator:
    """Random generator of one sampling chunk of one stage of a run."""
    key = [_check_seed(seed), stage, chunk]
    return np.random.default_rng(np.random.SeedSequence(key))


def sample_seeds(seed: int, stage: int, ids: np.ndarray) -> np.ndarray:
    """One ``int64`` seed per sample id of a stage, same shape as ``ids``.

    Seed ``i`` is the SplitMix64 hash of a stage key plus ``i``: it depends only
    on the run seed, the stage and the sample id.
    """
    sequence = np.random.SeedSequence([_check_seed(seed), stage, 1])
    key = sequence.generate_state(1, np.uint64)[0]
    z = key + np.asarray(ids, dtype=np.uint64) * _SPLITMIX_GAMMA
    with np.errstate(over="ignore"):
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(1)).astype(np.int64)


def _check_seed(seed: int) -> int:
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed}")
    return int(seed)


def check_positive_int(name: str, value: Any, minimum: int = 1) -> int:
    """Return ``value`` as an int, or raise naming it if it is not ``>= minimum``."""
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def threshold_list(gamma_test: Sequence[float] | float) -> tuple[float, ...]:
    """Accept one test threshold or a sequence of them."""
    return (float(gamma_test),) if np.isscalar(gamma_test) else tuple(gamma_test)
