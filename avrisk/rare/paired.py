"""Paired comparison of two versions of a black box on common random numbers.

Two versions ``A`` and ``B`` of a system (two releases of a policy) are
compared on the same draws of ``X ~ P0``: a paired black box maps each row
``x`` (and its seed, for a seeded one) to both outcomes, ``(f_A(x),
f_B(x))``, so that what differs between them is the version alone. The events
are ``A = {f_A <= gamma}`` and ``B = {f_B <= gamma}``.

Search. Subset simulation followed by importance sampling
(:func:`~avrisk.rare.splitting_importance.splitting_is`) runs on ``min(f_A,
f_B)``, whose event ``{min <= gamma}`` is the union ``A or B``: its levels and
its fitted proposal cover both failure sets (a region only one version fails
in is a region of the union), and its final stage draws ``n`` samples of the
proposal ``q`` with weights ``w = p0 / q``. Each sample carries both outcomes
(recorded beside ``f`` as the columns ``f_a`` and ``f_b``).

Estimates. From that one weighted sample, with ``a_i = 1{f_A(x_i) <=
gamma}`` and ``b_i`` alike:

* ``p_A = mean(w a)``, ``p_B = mean(w b)``, each with the importance
  sampler's standard error and diagnostics
  (:func:`~avrisk.rare.final_stage.weighted_hits_estimate`);
* ``p_B - p_A = mean(w (b - a))``: a paired difference, whose terms are zero
  wherever the versions agree, so its standard error ``std(w (b - a)) /
  sqrt(n)`` comes from the discordant samples alone, not from two
  independent errors added;
* ``p_B / p_A``: Fieller's interval for a ratio of the two correlated means
  (the set of ``R`` whose ``mean(w (b - R a))`` is within ``z`` standard
  errors of 0, the covariance of ``w a`` and ``w b`` in it); unbounded above
  when ``p_A`` is not clearly above 0;
* the discordant shares: regressions (``B`` fails, ``A`` does not: ``mean(w
  b (1 - a))``, as a share of ``p_B``) and fixes (the reverse, as a share of
  ``p_A``); ``p_B - p_A`` is their difference.

No discordant sample. Then the sample's own spread of the difference is 0,
yet the versions may differ where no sample fell. The bound is the one a
naive sample with no hit gives: among the union's ``m`` effective hits (Kish
ESS of their weights) none was discordant, so ``P(A xor B | A or B) <= 1 -
alpha^(1 / m)`` at one-sided level ``1 - alpha``, and ``|p_B - p_A| <=
P(A xor B)`` is at most that share of the union's upper bound. The
difference's interval is ``+-`` that bound, and the ratio's ``1 +-`` it over
``p_A``'s lower bound: never of zero width.

Trust. The engine's one rule (:mod:`avrisk.rare.trust`): the union's search
and estimate (:func:`~avrisk.rare.trust.estimate_trust` of ``splitting_is``),
then each version's estimate and the discordant samples' estimate
(:func:`~avrisk.rare.trust.trust_at`), in words naming which.

Calls. One call of the paired box evaluates both versions on a row;
``n_evals`` counts calls (pairs of evaluations).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.final_stage import (
    CONFIDENCE,
    bracket_failures,
    weighted_hits_estimate,
)
from avrisk.rare.problem import FINAL_STAGE, BatchFunction, InvalidOutputError
from avrisk.rare.results import GammaEstimate, jsonable
from avrisk.rare.splitting_importance import (
    SplittingImportanceSampling,
    SplittingISSettings,
    splitting_is,
)
from avrisk.rare.stages import BatchCache, BatchRecorder, StageBatch
from avrisk.rare.trust import GENERIC, Trust, Wording, estimate_trust, trust_at
from avrisk.rare.weights import kish_ess

__all__ = [
    "PAIR_COLUMNS",
    "UNION_METHOD",
    "Contrast",
    "FinalStageTap",
    "PairedEstimate",
    "PairedSample",
    "discordance_bound",
    "fieller_interval",
    "MinOfPair",
    "paired_estimate",
    "Verdict",
    "gate",
    "paired_splitting_is",
]

#: The estimator that searches the union of the two failure sets.
UNION_METHOD = SplittingImportanceSampling.name
#: The recorded columns of each version's outcome, A's first.
PAIR_COLUMNS = ("f_a", "f_b")

#: Interval descriptions of :class:`Contrast`.
PAIRED_NORMAL = (
    "normal approximation of the paired weighted mean (CLT over the one "
    "weighted sample both versions share)"
)
FIELLER = (
    "Fieller's interval for the ratio of the two correlated weighted means "
    "(their covariance from the one weighted sample both versions share)"
)
DISCORDANCE_BOUND = (
    "bound from no discordant sample: P(A xor B) at most the zero-hit bound of "
    "its share of the union's effective hits, times the union's upper bound"
)


@dataclass(frozen=True)
class Contrast:
    """A difference or a ratio of ``p_B`` and ``p_A``, with its intervals.

    Attributes
    ----------
    value : float
        The estimate (``inf`` or NaN for a ratio over ``p_A = 0``).
    stderr : float
        Its standard error (delta method for a ratio); 0 with no discordant
        sample.
    ci : tuple of float
        Two-sided interval at level ``confidence``.
    lower, upper : float
        One-sided bounds at level ``confidence`` each (``P(true < lower) <=
        1 - confidence``): what a one-sided test reads (a CI gate).
    confidence : float
    interval : str
        How the intervals were computed, in words.
    """

    value: float
    stderr: float
    ci: tuple[float, float]
    lower: float
    upper: float
    confidence: float = CONFIDENCE
    interval: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite floats become ``None``)."""
        return jsonable(dataclasses.asdict(self))


@dataclass(frozen=True)
class PairedSample:
    """The final weighted sample with both versions' outcomes.

    Attributes
    ----------
    log_w : ndarray of shape (n,)
        ``log p0 - log q`` of each sample.
    f_a, f_b : ndarray of shape (n,)
        Each version's value (NaN where the evaluation failed).
    failed : ndarray of bool, shape (n,)
        Samples whose evaluation failed (counted safe for both versions).
    """

    log_w: FloatArray
    f_a: FloatArray
    f_b: FloatArray
    failed: np.ndarray


@dataclass(frozen=True)
class PairedEstimate:
    """Both versions' failure probabilities and their contrast, from one sample.

    Attributes
    ----------
    gamma : float
        Threshold of failure, ``f <= gamma``.
    a, b : GammaEstimate
        ``p_A`` and ``p_B`` (each with its hits, ESS and Pareto k).
    difference : Contrast
        ``p_B - p_A``.
    ratio : Contrast
        ``p_B / p_A``.
    regressions : GammaEstimate
        ``P(B fails, A does not)``, its ``n_hits`` those samples.
    fixes : GammaEstimate
        ``P(A fails, B does not)``.
    union : dict
        The search's estimate of ``P(A or B)`` (``splitting_is`` on ``min(f_A,
        f_B)``), as ``Estimate.to_dict()`` (a run summary's ``estimate``).
    trust : Trust
        The engine's trust rule on the union, each version and the
        discordant samples.
    """

    gamma: float
    a: GammaEstimate
    b: GammaEstimate
    difference: Contrast
    ratio: Contrast
    regressions: GammaEstimate
    fixes: GammaEstimate
    union: dict[str, Any]
    trust: Trust

    @property
    def n_evals(self) -> int:
        """Calls of the paired box (each evaluates both versions)."""
        return int(self.union["n_evals"])

    @property
    def regression_share(self) -> float:
        """Share of ``p_B`` in samples ``A`` does not fail (NaN for ``p_B = 0``)."""
        return self.regressions.p / self.b.p if self.b.p > 0 else math.nan

    @property
    def fix_share(self) -> float:
        """Share of ``p_A`` in samples ``B`` does not fail (NaN for ``p_A = 0``)."""
        return self.fixes.p / self.a.p if self.a.p > 0 else math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of every figure (the union's as ``to_dict``)."""
        return jsonable(
            {
                "gamma": self.gamma,
                "a": self.a.to_dict(),
                "b": self.b.to_dict(),
                "difference": self.difference.to_dict(),
                "ratio": self.ratio.to_dict(),
                "regressions": self.regressions.to_dict(),
                "regression_share": self.regression_share,
                "fixes": self.fixes.to_dict(),
                "fix_share": self.fix_share,
                "n_evals": self.n_evals,
                "trust": {"word": self.trust.word, "reasons": list(self.trust.reasons)},
                "union": self.union,
            }
        )

    def __str__(self) -> str:
        lo, hi = self.ratio.ci
        return (
            f"p_A = {self.a.p:.3g}, p_B = {self.b.p:.3g}, p_B / p_A = "
            f"{self.ratio.value:.3g} (95% CI [{lo:.3g}, {hi:.3g}]), "
            f"{self.regressions.n_hits} regressions and {self.fixes.n_hits} fixes "
            f"sampled, {self.n_evals} paired calls; {self.trust}"
        )


class MinOfPair:
    """The black box ``min(f_A, f_B)`` of a paired one, both values kept.

    Parameters
    ----------
    pair : callable
        ``pair(x)`` (or ``pair(x, seeds=...)`` with ``needs_seeds = True``)
        returns an ``(n, 2)`` array of ``(f_A, f_B)``, or a mapping with it
        under ``"f"`` and other per-sample outputs (``"status"`` ...) as
        ``(n,)`` arrays.

    Returns (when called)
    ---------------------
    dict
        ``f``: ``min(f_A, f_B)`` (NaN where either is), ``f_a``, ``f_b``,
        and the pair's other outputs.
    """

    def __init__(self, pair: BatchFunction) -> None:
        self.pair = pair
        self.needs_seeds = bool(getattr(pair, "needs_seeds", False))

    def __call__(
        self, x: FloatArray, seeds: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """``f``: ``min(f_A, f_B)`` (NaN where either is), ``f_a``, ``f_b``, the rest.

        Raises
        ------
        InvalidOutputError
            If the pair's values are not of shape (n, 2).
        """
        out = self.pair(x, seeds=seeds) if self.needs_seeds else self.pair(x)
        extras: dict[str, Any] = {}
        if isinstance(out, Mapping):
            extras = {k: v for k, v in out.items() if k != "f"}
            out = out["f"]
        values = np.asarray(out, dtype=np.float64)
        if values.shape != (len(x), 2):
            raise InvalidOutputError(
                f"a paired f must return an array of shape ({len(x)}, 2) (f_A, "
                f"f_B) for {len(x)} input rows; got shape {values.shape}"
            )
        f_a, f_b = values[:, 0], values[:, 1]
        return {"f": np.minimum(f_a, f_b), "f_a": f_a, "f_b": f_b, **extras}


class FinalStageTap:
    """Keeps the final stage's chunks, evaluated or replayed, on their way.

    Wraps a run's ``on_batch`` and ``cache`` (either may be None): every
    chunk of :data:`~avrisk.rare.problem.FINAL_STAGE` that is evaluated or
    replayed is kept (a re-evaluated chunk replaces its replay), and passed on
    unchanged; the others pass through. The estimator is not changed: the tap
    sees what the run's record sees.
    """

    def __init__(
        self, on_batch: BatchRecorder | None = None, cache: BatchCache | None = None
    ) -> None:
        self._on_batch = on_batch
        self._cache = cache
        self.chunks: dict[int, StageBatch] = {}

    def record(self, batch: StageBatch) -> None:
        """``on_batch`` of the run."""
        if batch.stage == FINAL_STAGE:
            self.chunks[batch.chunk] = batch
        if self._on_batch is not None:
            self._on_batch(batch)

    def replay(self, stage: int, chunk: int) -> StageBatch | None:
        """``cache`` of the run."""
        batch = self._cache(stage, chunk) if self._cache is not None else None
        if batch is not None and stage == FINAL_STAGE:
            self.chunks[chunk] = batch
        return batch

    def sample(self, n: int) -> PairedSample:
        """The first ``n`` samples of the final stage (its chunks in order).

        Raises
        ------
        RuntimeError
            If a chunk is missing or lacks the pair's columns.
        """
        ordered, total = [], 0
        while total < n:
            batch = self.chunks.get(len(ordered))
            if batch is None or not set(PAIR_COLUMNS) <= set(batch.extras):
                raise RuntimeError(
                    f"chunk {len(ordered)} of the final stage was not seen with both "
                    f"versions' values ({', '.join(PAIR_COLUMNS)})"
                )
            ordered.append(batch)
            total += batch.values.size

        def column(get: Callable[[StageBatch], np.ndarray]) -> np.ndarray:
            return np.concatenate([get(b) for b in ordered])[:n]

        return PairedSample(
            column(lambda b: b.log_p0 - b.log_q),
            column(lambda b: np.asarray(b.extras["f_a"], dtype=np.float64)),
            column(lambda b: np.asarray(b.extras["f_b"], dtype=np.float64)),
            column(lambda b: b.failed),
        )


def _z(one_sided: float) -> float:
    """The standard normal quantile of one-sided level ``one_sided``."""
    return float(stats.norm.ppf(one_sided))


#: Normal quantiles of the two-sided interval and of the one-sided bounds.
Z_TWO_SIDED = _z(0.5 + CONFIDENCE / 2)
Z_ONE_SIDED = _z(CONFIDENCE)


def discordance_bound(
    log_w: FloatArray, union: np.ndarray, union_upper: float
) -> float:
    """Upper bound of ``P(A xor B)`` when no sample of the union is discordant.

    Parameters
    ----------
    log_w : ndarray of shape (n,)
        Log-weights of the sample.
    union : ndarray of bool, shape (n,)
        Samples in ``A or B``.
    union_upper : float
        Upper end of the union's two-sided interval (a one-sided bound at
        ``(1 + CONFIDENCE) / 2``).

    Returns
    -------
    float
        ``union_upper (1 - alpha^(1 / m))``, ``m`` the Kish ESS of the union's
        hits and ``alpha = (1 - CONFIDENCE) / 2``: the exact bound of a share
        seen 0 times in ``m`` draws, at the same one-sided level as
        ``union_upper``, so that both hold together at ``CONFIDENCE``.
        ``union_upper`` itself without a hit.

    Examples
    --------
    >>> # 0.1 (1 - 0.025^(1/4)): 4 equally weighted hits, none discordant
    >>> round(discordance_bound(np.zeros(4), np.ones(4, bool), 0.1), 4)
    0.0602
    """
    m = kish_ess(log_w[union])
    if m <= 0.0:
        return float(union_upper)
    alpha = (1.0 - CONFIDENCE) / 2.0
    return float(union_upper * -math.expm1(math.log(alpha) / m))


def fieller_interval(
    means: tuple[float, float], cov: FloatArray, z: float
) -> tuple[float, float]:
    """Fieller's interval of ``mean_b / mean_a``, two correlated means, in ``[0, inf]``.

    The set of ``R >= 0`` with ``(mean_b - R mean_a)^2 <= z^2 Var(mean_b - R
    mean_a)``, ``Var = v_bb - 2 R v_ab + R^2 v_aa``: exact for normal means.
    Bounded when ``mean_a`` is more than ``z`` standard errors above 0;
    otherwise it reaches ``inf`` (and starts at 0 unless ``mean_b`` is more
    than ``z`` standard errors above 0). Its ends at ``z`` for a one-sided
    level are the one-sided bounds at that level.

    Parameters
    ----------
    means : (float, float)
        ``mean_a``, ``mean_b``.
    cov : ndarray of shape (2, 2)
        Covariance matrix of the two means (not of single terms).
    z : float
        Normal quantile.

    Examples
    --------
    >>> lo, hi = fieller_interval((1.0, 2.0), np.diag([0.01, 0.01]), 1.96)
    >>> round(lo, 3), round(hi, 3)
    (1.626, 2.534)
    """
    a, b = means
    z2 = z * z
    quad = float(a * a - z2 * cov[0, 0])
    half = float(a * b - z2 * cov[0, 1])
    const = float(b * b - z2 * cov[1, 1])
    disc = max(half * half - quad * const, 0.0)
    if quad > 0.0:
        low, high = (half - math.sqrt(disc)) / quad, (half + math.sqrt(disc)) / quad
        return max(low, 0.0), max(high, 0.0)
    if const <= 0.0:  # neither mean clearly above 0
        return 0.0, math.inf
    # quad <= 0 < const: positive at 0, it falls below 0 past its one
    # positive root (the roots' product const / quad is negative)
    if quad < 0.0:
        return (half - math.sqrt(disc)) / quad, math.inf
    return (const / (2.0 * half) if half > 0.0 else 0.0), math.inf


def _difference(
    terms: tuple[FloatArray, FloatArray], scale: float, bound: float | None
) -> Contrast:
    """``p_B - p_A`` from scaled terms ``w a``, ``w b`` (``bound``: none discordant)."""
    if bound is not None:
        return Contrast(
            0.0, 0.0, (-bound, bound), -bound, bound, CONFIDENCE, DISCORDANCE_BOUND
        )
    d = (terms[1] - terms[0]) * scale
    value = float(d.mean())
    se = float(d.std(ddof=1) / math.sqrt(d.size))
    return Contrast(
        value,
        se,
        (value - Z_TWO_SIDED * se, value + Z_TWO_SIDED * se),
        value - Z_ONE_SIDED * se,
        value + Z_ONE_SIDED * se,
        CONFIDENCE,
        PAIRED_NORMAL,
    )


def _ratio(
    terms: tuple[FloatArray, FloatArray], a: GammaEstimate, bound: float | None
) -> Contrast:
    """``p_B / p_A`` from the scaled terms (``bound``: none discordant; ``a``: p_A)."""
    wa, wb = terms
    n = wa.size
    mean_a, mean_b = float(wa.mean()), float(wb.mean())
    if mean_a > 0.0:
        value = mean_b / mean_a
        se = float((wb - value * wa).std(ddof=1) / math.sqrt(n) / mean_a)
    else:
        value, se = (math.inf if mean_b > 0.0 else math.nan), math.inf
    if bound is not None:  # p_B / p_A = 1 + (p_B - p_A) / p_A
        half = bound / a.ci[0] if a.ci[0] > 0.0 else math.inf
        ends = (max(1.0 - half, 0.0), 1.0 + half)
        return Contrast(value, 0.0, ends, *ends, CONFIDENCE, DISCORDANCE_BOUND)
    cov = np.cov(np.stack([wa, wb])) / n
    ci = fieller_interval((mean_a, mean_b), cov, Z_TWO_SIDED)
    lower, upper = fieller_interval((mean_a, mean_b), cov, Z_ONE_SIDED)
    return Contrast(value, se, ci, lower, upper, CONFIDENCE, FIELLER)


def _versions_words(wording: Wording) -> dict[str, Wording]:
    """How trust reasons name the union, each version and the discordant samples."""
    m = wording.measure

    def named(measure: str) -> Wording:
        return dataclasses.replace(wording, measure=measure)

    return {
        "union": named(f"{m} of A or of B"),
        "a": named(f"{m} of A"),
        "b": named(f"{m} of B"),
        "xor": named(f"{m} of exactly one of A and B"),
    }


def paired_trust(
    union: Mapping[str, Any],
    parts: Mapping[str, GammaEstimate],
    wording: Wording = GENERIC,
) -> Trust:
    """The engine's trust rule on a paired estimate, each reason once.

    ``union``: the search's estimate as a dictionary
    (:func:`~avrisk.rare.trust.estimate_trust` of ``splitting_is``, at its
    ``gamma``); ``parts``: the estimates of ``"a"``, ``"b"`` and
    ``"xor"`` (the discordant samples), each read by
    :func:`~avrisk.rare.trust.trust_at` as a weighted estimate.
    """
    words = _versions_words(wording)
    reasons = list(
        estimate_trust(
            SplittingImportanceSampling, union, _main(union), words["union"]
        ).reasons
    )
    for key, part in parts.items():
        reasons.extend(trust_at(part.to_dict(), True, words[key]).reasons)
    return Trust(tuple(dict.fromkeys(reasons)))


def _main(union: Mapping[str, Any]) -> dict[str, Any]:
    """The entry of an estimate dictionary's ``by_gamma`` at its ``gamma``."""
    return next(g for g in union["by_gamma"] if g["gamma"] == union["gamma"])


def paired_estimate(
    sample: PairedSample,
    gamma: float,
    union: Mapping[str, Any],
    wording: Wording = GENERIC,
) -> PairedEstimate:
    """Every estimate of the module docstring from one weighted paired sample.

    Parameters
    ----------
    sample : PairedSample
        The final stage's samples with both versions' values (``n >= 2``).
    gamma : float
        Failure threshold.
    union : mapping
        The search's estimate of ``P(A or B)`` from the same sample, as
        ``Estimate.to_dict()``.
    wording : Wording, default=GENERIC
        How trust reasons name ``f`` and a sample.
    """
    log_w, failed = sample.log_w, sample.failed
    a_hit = np.where(failed, False, sample.f_a <= gamma)
    b_hit = np.where(failed, False, sample.f_b <= gamma)
    either = a_hit | b_hit
    shift = float(log_w[either].max()) if either.any() else 0.0
    w = np.where(either, np.exp(np.where(either, log_w, shift) - shift), 0.0)
    terms = (w * a_hit, w * b_hit)

    def version(values: FloatArray) -> GammaEstimate:
        return bracket_failures(
            lambda v: {gamma: weighted_hits_estimate(log_w, v <= gamma, gamma)},
            values,
            failed,
        )[gamma]

    a, b = version(sample.f_a), version(sample.f_b)
    union_upper = weighted_hits_estimate(log_w, either, gamma).ci[1]
    discordant = a_hit ^ b_hit
    bound = None if discordant.any() else discordance_bound(log_w, either, union_upper)

    def share(hits: np.ndarray) -> GammaEstimate:
        est = weighted_hits_estimate(log_w, hits, gamma)
        if est.n_hits or bound is None:
            return est
        return dataclasses.replace(est, ci=(0.0, bound), interval=DISCORDANCE_BOUND)

    return PairedEstimate(
        gamma=gamma,
        a=a,
        b=b,
        difference=_difference(terms, math.exp(shift), bound),
        ratio=_ratio(terms, a, bound),
        regressions=share(b_hit & ~a_hit),
        fixes=share(a_hit & ~b_hit),
        union=dict(union),
        trust=paired_trust(
            union,
            {"a": a, "b": b, "xor": weighted_hits_estimate(log_w, discordant, gamma)},
            wording,
        ),
    )


def paired_splitting_is(
    pair: BatchFunction,
    base: ExponentialFamily,
    gamma: float,
    *,
    settings: SplittingISSettings | None = None,
    seed: int = 0,
    batch_size: int | None = None,
    on_batch: BatchRecorder | None = None,
    cache: BatchCache | None = None,
    wording: Wording = GENERIC,
    **options: Any,
) -> PairedEstimate:
    """Compare ``P0(f_A <= gamma)`` and ``P0(f_B <= gamma)`` on common samples.

    Parameters
    ----------
    pair : callable
        Paired black box (:class:`MinOfPair`): rows ``x`` of shape (n, D) to
        ``(n, 2)`` values ``(f_A, f_B)``, or a mapping with them under
        ``"f"``; seeded like any black box (``needs_seeds``).
    base : ExponentialFamily
        ``P0``; it must map to standard normals.
    gamma : float
        Failure threshold of both versions.
    settings : SplittingISSettings, optional
        The search's settings (:func:`~avrisk.rare.splitting_importance.splitting_is`).
    seed, batch_size : int
        As for ``splitting_is``.
    on_batch, cache : callable, optional
        A run's record and replay of its chunks (resume), as for ``splitting_is``.
    wording : Wording, default=GENERIC
        How trust reasons name ``f`` and a sample.
    **options
        ``splitting_is``'s other arguments (``callback``, ``evaluator``,
        ``stopping``) and settings by name.

    Returns
    -------
    PairedEstimate

    Raises
    ------
    SplittingError
        If the levels cannot reach ``gamma``.

    Examples
    --------
    >>> from avrisk.rare import FixedCovNormal
    >>> base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    >>> pair = lambda x: np.stack([3.5 - x[:, 0], 3.6 - x[:, 0]], axis=1)  # B in A
    >>> est = paired_splitting_is(pair, base, 0.0, n_particles=1000, n_final=4000)
    >>> est.fixes.n_hits > 0, est.regressions.n_hits
    (True, 0)
    >>> bool(est.ratio.ci[0] < 0.684 < est.ratio.ci[1])  # Phi(-3.6) / Phi(-3.5)
    True
    """
    tap = FinalStageTap(on_batch, cache)
    union = splitting_is(
        MinOfPair(pair),
        base,
        gamma,
        settings=settings,
        seed=seed,
        batch_size=batch_size,
        on_batch=tap.record,
        cache=tap.replay,
        **options,
    )
    if not tap.chunks:  # the levels ended with a bound and no final stage
        return bound_only(union.to_dict(), wording)
    sample = tap.sample(union.n_samples)
    return paired_estimate(sample, union.gamma, union.to_dict(), wording)


def bound_only(union: Mapping[str, Any], wording: Wording = GENERIC) -> PairedEstimate:
    """A search that found no sample of the union: every figure a bound.

    ``p_A``, ``p_B`` and the discordant shares are 0 with the union's bound
    (``union``: its estimate as a dictionary) as upper end, the difference
    ``+-`` it, and the ratio unbounded.
    """
    main = _main(union)
    high = float(main["ci"][1])
    zero = GammaEstimate(
        gamma=float(union["gamma"]),
        p=0.0,
        stderr=0.0,
        ci=(0.0, high),
        n_hits=0,
        ess=0.0,
        n_samples=int(main["n_samples"]),
        interval=main.get("interval") or "",
    )
    difference = Contrast(
        0.0, 0.0, (-high, high), -high, high, CONFIDENCE, zero.interval
    )
    ratio = Contrast(
        math.nan, math.inf, (0.0, math.inf), 0.0, math.inf, CONFIDENCE, zero.interval
    )
    parts = {"a": zero, "b": zero, "xor": zero}
    return PairedEstimate(
        zero.gamma,
        zero,
        zero,
        difference,
        ratio,
        zero,
        zero,
        dict(union),
        paired_trust(union, parts, wording),
    )


@dataclass(frozen=True)
class Verdict:
    """A one-sided test of ``p_B / p_A`` against a margin (a release gate).

    Attributes
    ----------
    outcome : str
        ``"pass"``: the one-sided upper bound of ``p_B / p_A`` is at most
        ``max_ratio``; ``"fail"``: the one-sided lower bound is above it;
        ``"inconclusive"`` otherwise. Each bound at level ``confidence``.
    max_ratio : float
        The margin.
    lower, upper : float
        The one-sided bounds of the ratio.
    n_final_needed : int or None
        For an inconclusive verdict, the final-stage samples at which the
        bound on the side of the estimate would reach the margin if the
        estimate stayed where it is (its standard error falling as one over
        the root of the samples); None otherwise, or when no number would
        (an estimate at the margin, or an unbounded ratio).
    confidence : float
    """

    outcome: str
    max_ratio: float
    lower: float
    upper: float
    n_final_needed: int | None = None
    confidence: float = CONFIDENCE

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite floats become ``None``)."""
        return jsonable(dataclasses.asdict(self))


def gate(estimate: PairedEstimate, max_ratio: float) -> Verdict:
    """Pass, fail or inconclusive: ``p_B / p_A`` against ``max_ratio``.

    Parameters
    ----------
    estimate : PairedEstimate
    max_ratio : float
        Largest acceptable ``p_B / p_A`` (1: ``B`` no riskier than ``A``).
    """
    ratio = estimate.ratio
    lower, upper = ratio.lower, ratio.upper
    if upper <= max_ratio:
        return Verdict("pass", max_ratio, lower, upper)
    if lower > max_ratio:
        return Verdict("fail", max_ratio, lower, upper)
    return Verdict(
        "inconclusive", max_ratio, lower, upper, _samples_to_decide(estimate, max_ratio)
    )


def _samples_to_decide(estimate: PairedEstimate, max_ratio: float) -> int | None:
    """Final-stage samples at which the ratio's bound would clear ``max_ratio``.

    The bound on the estimate's side of the margin is ``z s`` away from it,
    ``s`` the standard error it implies; at ``n`` samples ``s`` scales as
    ``1 / sqrt(n)``, so it clears the margin at ``n (z s / |R - max_ratio|)^2``.
    """
    ratio = estimate.ratio
    gap = ratio.value - max_ratio
    spread = ratio.upper - ratio.value if gap < 0 else ratio.value - ratio.lower
    n_final = estimate.a.n_samples
    if gap == 0 or not math.isfinite(spread) or not math.isfinite(gap):
        return None
    return math.ceil(n_final * (spread / abs(gap)) ** 2)
