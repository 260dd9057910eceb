"""Result objects of the estimators: frozen, JSON-serialisable."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol


class Proposal(Protocol):
    """The distribution of a final stage: a family, or a mixture of them."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description."""
        ...


@dataclass(frozen=True)
class GammaEstimate:
    """Estimate of ``p = P0(f(X) <= gamma)`` for one threshold.

    Attributes
    ----------
    gamma : float
        Threshold, in the unit of ``f``.
    p : float
        Estimate of the probability.
    stderr : float
        Standard error of ``p`` (from the sample variance of the weighted
        indicators; binomial for naive Monte Carlo).
    ci : tuple of float
        Confidence interval ``(low, high)`` at level ``confidence``. With zero
        hits it is still an interval with a positive upper end.
    n_hits : int
        Samples of the final stage with ``f <= gamma``.
    ess : float
        Kish effective sample size of the weighted indicators ``w_i 1{f_i <=
        gamma}``: the number of equally weighted hits that would carry the same
        information (equals ``n_hits`` for naive Monte Carlo).
    n_samples : int
        Size of the final stage.
    confidence : float
        Level of ``ci``.
    pareto_k : float
        Tail index of the hits' weights
        (:func:`avrisk.rare.weights.pareto_tail_index`): above 0.7 the standard
        error is unreliable. NaN for naive Monte Carlo and for too few hits.
    n_failed : int
        Samples whose evaluation failed (:mod:`avrisk.rare.evaluation`). They
        are counted safe in ``p``, ``stderr`` and ``n_hits``;
        ``p_if_failed_dangerous`` counts them dangerous, and ``ci`` spans both.
    p_if_failed_dangerous : float
        The estimate with the failed samples counted dangerous (the upper end
        of the bracket; equals ``p`` when none failed).
    interval : str
        How ``ci`` was computed, in words (shown in summaries and reports).
    """

    gamma: float
    p: float
    stderr: float
    ci: tuple[float, float]
    n_hits: int
    ess: float
    n_samples: int
    confidence: float = 0.95
    pareto_k: float = math.nan
    n_failed: int = 0
    p_if_failed_dangerous: float = math.nan
    interval: str = ""

    def __post_init__(self) -> None:
        if math.isnan(self.p_if_failed_dangerous):
            object.__setattr__(self, "p_if_failed_dangerous", self.p)

    @property
    def rel_error(self) -> float:
        """Coefficient of variation ``stderr / p`` (``inf`` when ``p = 0``)."""
        return self.stderr / self.p if self.p > 0 else math.inf

    @property
    def variance_reduction(self) -> float:
        """Variance of naive MC at the same n over this variance.

        ``p (1 - p) / n / stderr^2``: how many times more samples naive Monte
        Carlo would need for the same standard error.
        """
        if self.stderr <= 0 or not 0 < self.p < 1:  # an IS estimate can exceed 1
            return math.nan
        if self.stderr**2 == 0.0:  # underflows (p about 1e-160 or less)
            return (self.p / self.stderr) ** 2 * (1 - self.p) / self.n_samples
        return self.p * (1 - self.p) / self.n_samples / self.stderr**2

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (non-finite floats become ``None``)."""
        return jsonable(
            {
                "gamma": self.gamma,
                "p": self.p,
                "stderr": self.stderr,
                "ci": list(self.ci),
                "confidence": self.confidence,
                "n_hits": self.n_hits,
                "ess": self.ess,
                "pareto_k": self.pareto_k,
                "n_samples": self.n_samples,
                "rel_error": self.rel_error,
                "variance_reduction": self.variance_reduction,
                "n_failed": self.n_failed,
                "p_if_failed_dangerous": self.p_if_failed_dangerous,
                "interval": self.interval,
            }
        )


class CEInfo(NamedTuple):
    """Diagnostics of one cross-entropy iteration (not needed by the next one).

    Attributes
    ----------
    iteration : int
        Index ``k`` of the iteration, from 0.
    gamma_k : float
        Level used for the update, ``max(gamma, quantile)``.
    quantile : float
        ``rho``-quantile of ``f`` under the proposal of this iteration.
    ess : float
        Kish effective sample size of the elite weights (the samples with
        ``f <= gamma_k``) that formed the target moment.
    n_elite : int
        Samples with ``f <= gamma_k``.
    n_hits : int
        Samples with ``f <= gamma``.
    n_evals : int
        Calls of ``f`` so far, this iteration included.
    rel_var : float
        Estimated relative variance per sample, ``Var(w 1{f <= gamma}) / p^2``,
        of importance sampling with this iteration's proposal, from its own
        samples (``inf`` without hits). The final stage's relative standard error
        would be about ``sqrt(rel_var / n_final)``.
    """

    iteration: int
    gamma_k: float
    quantile: float
    ess: float
    n_elite: int
    n_hits: int
    n_evals: int
    rel_var: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return jsonable(self._asdict())


@dataclass(frozen=True)
class SearchConvergence:
    """Whether an adaptive search reached a threshold and stayed there.

    A cross-entropy search lowers its level ``gamma_k`` (the ``rho``-quantile
    of ``f`` under the proposal of iteration ``k``) towards ``gamma``. It has
    converged for ``gamma`` when some iteration's quantile reached it (at
    least a share ``rho`` of that proposal's samples were hits, so the
    updates were fitted to the event itself) and the last iteration's still
    did (the proposal settled there rather than drifting away again).

    Attributes
    ----------
    gamma : float
        The threshold, in the unit of ``f``.
    n_iter : int
        Iterations of the search.
    reached_at : int or None
        First iteration (from 0) whose quantile was at most ``gamma``; None
        if none was.
    lowest : float
        Lowest quantile of any iteration.
    last : float
        Quantile of the last iteration.
    """

    gamma: float
    n_iter: int
    reached_at: int | None
    lowest: float
    last: float

    @property
    def converged(self) -> bool:
        """Reached ``gamma``, and held it at the last iteration."""
        return self.reached_at is not None and self.last <= self.gamma

    def sentence(self, measure: str = "f", unit: str = "") -> str:
        """What the search did, in one clause (a reason when not converged).

        ``measure`` names ``f`` and ``unit`` follows its values (``"min TTC"``
        and ``" s"`` say it of a time to collision).
        """
        g = f"{measure} <= {self.gamma:g}{unit}"
        if self.reached_at is None:
            return (
                f"the search did not reach {g}: its lowest rho-quantile of {measure} "
                f"in {self.n_iter} iterations was {self.lowest:.3g}{unit}, so its "
                "proposal aims at a less rare event (raise n_iter or rho)"
            )
        after = f"after {self.reached_at + 1} of its {self.n_iter} iterations"
        if not self.converged:
            return (
                f"the search reached {g} {after} but its last iteration's "
                f"rho-quantile of {measure} was back at {self.last:.3g}{unit}: the "
                "proposal had not settled (raise n_per_iter)"
            )
        return f"the search reached {g} {after} and held it (converged)"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with ``converged``."""
        return jsonable(
            {
                "gamma": self.gamma,
                "converged": self.converged,
                "n_iter": self.n_iter,
                "reached_at": self.reached_at,
                "lowest_quantile": self.lowest,
                "last_quantile": self.last,
            }
        )


class MixtureInfo(NamedTuple):
    """Diagnostics of one mixture cross-entropy iteration (:mod:`avrisk.rare.mixture`).

    Attributes
    ----------
    iteration, gamma_k, quantile, ess, n_elite, n_hits, n_evals, rel_var
        As in :class:`CEInfo`, for the mixture sampled at this iteration.
    n_components : int
        Live components of the mixture fitted at this iteration (after deaths
        and merges), the proposal of the next one.
    weights : tuple of float
        Their mixture weights ``pi_k`` (summing to one; the defensive share of
        ``P0`` comes on top).
    """

    iteration: int
    gamma_k: float
    quantile: float
    ess: float
    n_elite: int
    n_hits: int
    n_evals: int
    rel_var: float
    n_components: int
    weights: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return jsonable(self._asdict())


@dataclass(frozen=True)
class Estimate:
    """Result of a rare-event estimator.

    The headline fields (``p``, ``stderr``, ``ci``, ``n_hits``, ``ess``) are those
    of the main threshold ``gamma``; ``by_gamma`` holds the same for ``gamma`` and
    every test threshold, keyed by the threshold as given.

    Attributes
    ----------
    method : str
        The estimator (``"naive_mc"``, ``"cross_entropy"``, ...).
    gamma : float
        Main threshold.
    by_gamma : dict of float to GammaEstimate
        Estimates for ``gamma`` and each ``gamma_test``.
    n_evals : int
        Every call of ``f``, search stages included.
    proposal : ExponentialFamily, MixtureProposal or None
        Proposal of the final stage (``None`` for naive Monte Carlo).
    history : tuple
        The diagnostics (``Info``, with ``to_dict()``) of every step of the
        estimator: one :class:`CEInfo` per cross-entropy iteration; empty for
        naive Monte Carlo.
    best_iteration : int or None
        Iteration whose proposal was chosen (lowest ``rho``-quantile).
    wall_time_s : float
        Wall-clock time of the whole estimate [s].
    details : dict
        Further JSON-ready results of the estimator (e.g. a level sequence).
    stopped_by : str
        What ended the run: ``"budget"`` (its planned size) or a stopping
        rule (``"precision"``, ``"max_rollouts"``, ``"wall_time"``; see
        :mod:`avrisk.rare.stopping`).
    """

    method: str
    gamma: float
    by_gamma: dict[float, GammaEstimate]
    n_evals: int
    proposal: Proposal | None = None
    history: tuple[Any, ...] = field(default_factory=tuple)
    best_iteration: int | None = None
    wall_time_s: float = 0.0
    details: dict[str, Any] = field(default_factory=dict)
    stopped_by: str = "budget"

    @property
    def main(self) -> GammaEstimate:
        """The estimate for the main threshold ``gamma``."""
        return self.by_gamma[self.gamma]

    @property
    def p(self) -> float:
        """Estimate of ``P0(f <= gamma)``."""
        return self.main.p

    @property
    def stderr(self) -> float:
        """Standard error of ``p``."""
        return self.main.stderr

    @property
    def ci(self) -> tuple[float, float]:
        """Confidence interval of ``p``."""
        return self.main.ci

    @property
    def n_hits(self) -> int:
        """Final-stage samples with ``f <= gamma``."""
        return self.main.n_hits

    @property
    def ess(self) -> float:
        """Effective number of hits of the final stage (see GammaEstimate)."""
        return self.main.ess

    @property
    def n_samples(self) -> int:
        """Size of the final stage."""
        return self.main.n_samples

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dictionary of everything above."""
        return jsonable(
            {
                "method": self.method,
                "gamma": self.gamma,
                "p": self.p,
                "stderr": self.stderr,
                "ci": list(self.ci),
                "n_hits": self.n_hits,
                "ess": self.ess,
                "n_samples": self.n_samples,
                "n_evals": self.n_evals,
                "wall_time_s": self.wall_time_s,
                "stopped_by": self.stopped_by,
                "by_gamma": [g.to_dict() for g in self.by_gamma.values()],
                "proposal": None if self.proposal is None else self.proposal.to_dict(),
                "best_iteration": self.best_iteration,
                "history": [h.to_dict() for h in self.history],
                **({"details": self.details} if self.details else {}),
            }
        )

    def __str__(self) -> str:
        """One line: p, its interval, hits, ESS, calls, and which estimate answered.

        ``details["answer"]`` names the estimate that answered where an
        estimator has two (``splitting_is``: ``importance_sampling`` or
        ``splitting``, the levels' product).
        """
        lo, hi = self.ci
        answer = (self.details or {}).get("answer")
        return (
            f"{self.method}: P(f <= {self.gamma:g}) = {self.p:.4g} "
            f"+- {self.stderr:.2g} "
            f"({self.main.confidence:.0%} CI [{lo:.3g}, {hi:.3g}], "
            f"{self.n_hits} hits, ESS {self.ess:.1f}, {self.n_evals} calls of f"
            + (f"; answer: {answer}" if answer else "")
            + ")"
        )


def jsonable(value: Any) -> Any:
    """Replace non-finite floats by ``None`` and tuples by lists, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


def doubting_check(
    estimate: dict[str, Any], name: str, gamma: float
) -> dict[str, Any] | None:
    """The record ``details[name]`` of a check made after an estimate, if it doubts.

    ``estimate`` is a summary's (:meth:`Estimate.to_dict`). A check (the
    proposal audit, the rays) speaks of the run's own ``gamma`` only: without
    the check, asked of a test threshold, or where it found nothing, None.
    """
    record = (estimate.get("details") or {}).get(name)
    if not record or not record.get("doubt") or gamma != estimate.get("gamma"):
        return None
    return record
