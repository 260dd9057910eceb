"""Stopping rules a user sets: precision reached, rollouts spent, time up.

An estimator's final stage is evaluated chunk by chunk; after each chunk the
rule looks at the *contiguous prefix* of chunks done (whatever order an
evaluator returns them in) and may end the stage there. The estimate then
comes from that prefix, and the result says which rule stopped it
(``Estimate.stopped_by``): ``"budget"`` (the planned size), ``"precision"``,
``"max_rollouts"`` or ``"wall_time"``. Precision and rollout rules depend on
the prefix only, so a resumed run stops at the same chunk; a wall-time stop
depends on the clock.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from avrisk.rare.families.base import FloatArray

__all__ = ["StoppingRule"]

#: z of a two-sided 95% interval.
_Z95 = 1.959963984540054


@dataclass(frozen=True)
class StoppingRule:
    """When to end a run's final stage early (whichever comes first).

    Parameters
    ----------
    rel_half_width : float or None
        Stop once the 95% interval of ``p`` at the main threshold has a
        half-width at most this fraction of ``p`` (normal approximation from
        the weighted hits; at least one hit).
    max_rollouts : int or None
        Stop before the calls of ``f`` (search included) exceed this.
    max_seconds : float or None
        Stop once this much wall time [s] has passed since the rule was made
        (the run's start).

    Examples
    --------
    >>> rule = StoppingRule(rel_half_width=0.5)
    >>> rule.reason(np.array([0.0, 1.0, 0.0, 1.0]), np.zeros(4), 0.5, 0)
    >>> rule.reason(np.zeros(100), np.zeros(100), 0.5, 0)
    'precision'
    """

    rel_half_width: float | None = None
    max_rollouts: int | None = None
    max_seconds: float | None = None
    started: float = field(default_factory=time.perf_counter, compare=False)

    def __post_init__(self) -> None:
        for name in ("rel_half_width", "max_rollouts", "max_seconds"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be > 0; got {value}")

    def reason(
        self,
        values: FloatArray,
        log_w: FloatArray,
        gamma: float,
        calls_before: int,
        next_chunk: int = 0,
    ) -> str | None:
        """Why the final stage should end after this prefix, or None.

        Parameters
        ----------
        values, log_w : ndarray of shape (m,)
            ``f`` and log-weights of the prefix done (NaN ``f``: failed, safe).
        gamma : float
            The main threshold.
        calls_before : int
            Calls of ``f`` made before the final stage.
        next_chunk : int, default=0
            Rows of the next chunk (a rollout cap stops before exceeding).
        """
        m = values.size
        if self.max_rollouts is not None and calls_before + m + next_chunk > (
            self.max_rollouts
        ):
            return "max_rollouts"
        if self.max_seconds is not None and (
            time.perf_counter() - self.started >= self.max_seconds
        ):
            return "wall_time"
        if self.rel_half_width is not None and m > 1:
            with np.errstate(over="ignore", invalid="ignore"):
                term = np.where(values <= gamma, np.exp(log_w), 0.0)
            p = float(term.mean())
            if p > 0 and math.isfinite(p):
                half = _Z95 * float(term.std(ddof=1)) / math.sqrt(m)
                if half <= self.rel_half_width * p:
                    return "precision"
        return None
