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
  ``p_A``); their difference is the plain ``mean(w (b - a))``.

Control variates. The proposal is a mixture (its fitted components and the
defensive ``P0``), and the number of draws each component made is random: on
two failure sets each fitted by a component of its own, that count's
randomness is much of the difference's variance. The components' density
ratios ``q_j / q``, of known mean 1, are regressed out of the terms ``w a``
and ``w b`` (:mod:`avrisk.rare.mixture_controls`, Owen & Zhou 2000): ``p_A``,
``p_B``, the difference and the ratio come from the controlled terms, where
each version has at least ``MIN_RELIABLE_ESS`` effective hits (the
intervals' descriptions say so).

A discordant side with no sample. When no sample has ``B`` failing and
``A`` not (or the reverse), the terms of that side are all 0, yet the
versions may differ where no sample fell. Its bound is the one a naive
sample with no hit gives: among the union's ``m`` effective hits (Kish ESS
of their weights) none was of that side, so its share of the union is at
most ``1 - alpha^(1 / m)`` at one-sided level ``1 - alpha``, and its mass at
most that share of the union's upper bound
(:func:`~avrisk.rare.paired_intervals.discordance_bound`). The difference's
interval is widened by it on that side, and the ratio's by it over
``p_A``'s lower bound; with no discordant sample at all both are that bound
alone: never of zero width, and never blind to the side a sample missed.

Trust. The engine's one rule (:mod:`avrisk.rare.trust`): the union's search
and estimate (:func:`~avrisk.rare.trust.estimate_trust` of ``splitting_is``),
then each version's estimate and the discordant samples' estimate
(:func:`~avrisk.rare.trust.trust_at`), in words naming which.

Calls. One call of the paired box evaluates both versions on a row;
``n_evals`` counts calls (pairs of evaluations). Unless told otherwise the
search runs with ``PAIRED_DEFAULTS``: its levels at half a single-version
run's default particles (two evaluations a particle, so they cost what that
run's levels cost), the rest of two default single-version runs' budget in
the final stage, since every figure's error is the final sample's (the
levels only place the proposal); no refresh at ``gamma``, as measured.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.final_stage import (
    CONFIDENCE,
    MIN_RELIABLE_ESS,
    bracket_failures,
    weighted_hits_estimate,
)
from avrisk.rare.intervals import normal_interval
from avrisk.rare.mixture_controls import controlled_terms
from avrisk.rare.paired_intervals import (
    CONTROLLED,
    DISCORDANCE_BOUND,
    Contrast,
    difference_contrast,
    discordance_bound,
    ratio_contrast,
)
from avrisk.rare.paired_sample import (
    PAIR_COLUMNS,
    FinalStageTap,
    MinOfPair,
    PairedSample,
)
from avrisk.rare.problem import BatchFunction
from avrisk.rare.results import GammaEstimate, jsonable
from avrisk.rare.splitting_importance import (
    SplittingImportanceSampling,
    SplittingISSettings,
    splitting_is,
)
from avrisk.rare.stages import BatchCache, BatchRecorder
from avrisk.rare.trust import GENERIC, Trust, Wording, estimate_trust, trust_at

__all__ = [
    "PAIRED_DEFAULTS",
    "PAIR_COLUMNS",
    "UNION_METHOD",
    "Contrast",
    "FinalStageTap",
    "MinOfPair",
    "PairedEstimate",
    "PairedSample",
    "bound_only",
    "paired_estimate",
    "paired_splitting_is",
    "paired_trust",
]

#: The estimator that searches the union of the two failure sets.
UNION_METHOD = SplittingImportanceSampling.name

#: The union's search settings where none are given (module docstring, *Calls*).
PAIRED_DEFAULTS = {"n_particles": 1000, "n_final": 18_000, "refresh_rounds": 0}


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

    (a, b), terms, ddof = _controlled(
        (version(sample.f_a), version(sample.f_b)),
        terms,
        sample.controls,
        math.exp(shift),
    )
    union_upper = weighted_hits_estimate(log_w, either, gamma).ci[1]
    discordant = a_hit ^ b_hit
    regressions, fixes = b_hit & ~a_hit, a_hit & ~b_hit
    bound = discordance_bound(log_w, either, union_upper)
    unseen = tuple(0.0 if hits.any() else bound for hits in (fixes, regressions))

    def share(hits: np.ndarray) -> GammaEstimate:
        est = weighted_hits_estimate(log_w, hits, gamma)
        if est.n_hits:
            return est
        return dataclasses.replace(est, ci=(0.0, bound), interval=DISCORDANCE_BOUND)

    return PairedEstimate(
        gamma=gamma,
        a=a,
        b=b,
        difference=difference_contrast(terms, math.exp(shift), unseen, ddof),
        ratio=ratio_contrast(terms, a, unseen, ddof),
        regressions=share(regressions),
        fixes=share(fixes),
        union=dict(union),
        trust=paired_trust(
            union,
            {"a": a, "b": b, "xor": weighted_hits_estimate(log_w, discordant, gamma)},
            wording,
        ),
    )


def _controlled(
    versions: tuple[GammaEstimate, GammaEstimate],
    terms: tuple[FloatArray, FloatArray],
    controls: FloatArray,
    scale: float,
) -> tuple[tuple[GammaEstimate, GammaEstimate], tuple[FloatArray, FloatArray], int]:
    """Both versions' estimates and terms with the proposal's control variates.

    The terms ``w a`` and ``w b`` (divided by ``scale``) less their fit on
    ``controls`` (:func:`~avrisk.rare.mixture_controls.controlled_terms`),
    and each version's ``p``, standard error and interval from them (its
    hits, ESS and Pareto k are the sample's; an upper end widened by failed
    samples stays). Unchanged, with ``ddof`` 1, where there are no controls,
    where a version has fewer than ``MIN_RELIABLE_ESS`` effective hits (too
    few for a fitted coefficient to be better than none) or where a
    controlled estimate is not positive.

    Returns
    -------
    versions, terms, ddof
        ``ddof``: the degrees of freedom of the terms' spread.
    """
    if controls.shape[1] == 0 or any(v.ess < MIN_RELIABLE_ESS for v in versions):
        return versions, terms, 1
    fit = controlled_terms(np.stack(terms, axis=1), controls)
    if fit.ddof == 1:  # nothing was fitted
        return versions, terms, 1
    t = fit.terms
    n = t.shape[0]
    means = t.mean(axis=0) * scale
    if (means <= 0.0).any():
        return versions, terms, 1

    def version(est: GammaEstimate, column: FloatArray, mean: float) -> GammaEstimate:
        p = float(mean)
        se = float(column.std(ddof=fit.ddof) * scale / math.sqrt(n))
        low, high = (float(end) for end in normal_interval(p, se, CONFIDENCE))
        if est.n_failed:  # failed samples counted dangerous: the bracket's end
            high = max(high, est.ci[1])
        return dataclasses.replace(
            est,
            p=p,
            stderr=se,
            ci=(low, high),
            interval=f"{est.interval}, with {CONTROLLED}",
        )

    controlled = (
        version(versions[0], t[:, 0], means[0]),
        version(versions[1], t[:, 1], means[1]),
    )
    return controlled, (t[:, 0], t[:, 1]), fit.ddof


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
        The search's settings (:func:`~avrisk.rare.splitting_importance.splitting_is`);
        none: ``PAIRED_DEFAULTS`` with the settings given by name over them.
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
    if settings is None:
        options = {**PAIRED_DEFAULTS, **options}
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
    sample = tap.sample(union.n_samples, union.proposal)
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
