"""What the particles predict of an importance sample, before it is drawn.

Subset simulation's particles follow ``P0(. | f <= gamma)``; weighed by a
proposal fitted without them (by folds of their chains), their weights
``p0 / q`` say region by region how that proposal's importance sample will
fare (:func:`held_out_weights`): what share of ``p`` it will miss and its
variance per draw where it covers. :mod:`avrisk.rare.particle_fit` uses them
to choose among fits and :mod:`avrisk.rare.splitting_is_answer` to choose the
answer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from scipy.special import logsumexp

from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.particle_shifts import log_ratios_to_base, with_light_regions

__all__ = [
    "PREDICTION_FOLDS",
    "Fitter",
    "HeldOutWeights",
    "cross_fitted_log_ratios",
    "held_out_weights",
]

#: Folds of the chains in :func:`held_out_weights`.
PREDICTION_FOLDS = 10

#: A proposal's fit to particles and their chains: its components, their
#: weights and the coordinates it shifts (the fits of
#: :mod:`avrisk.rare.particle_shifts` with their settings bound).
Fitter = Callable[
    [FloatArray, np.ndarray],
    tuple[list[ExponentialFamily], FloatArray, np.ndarray],
]


class HeldOutWeights(NamedTuple):
    """What the particles' held-out weights ``w = p0 / q`` predict of the IS stage.

    The particles follow ``P0(. | f <= gamma)``, so averages over them are
    conditional expectations given the event ``F``. Where ``q <= p0`` (``w
    >= 1``) the proposal is no denser than ``P0``, and in a rare event its
    draws all but never land: importance sampling misses that part of ``p``
    (a bias its own interval does not show, not a variance). Elsewhere its
    draws' ``w 1{F, w < 1}`` have relative variance ``E[w 1{w < 1} | F] / p -
    (1 - s)^2`` per draw (``E_q[(w 1_F)^2] = p E[w | F]``).

    Attributes
    ----------
    uncovered : float
        ``s``, the share of particles with ``w >= 1``: of ``p``, the part the
        importance sample will miss.
    covered_mean_weight : float
        ``E[w 1{w < 1} | F]``, the particles' mean weight where ``w < 1``
        (0 counted elsewhere).
    """

    uncovered: float
    covered_mean_weight: float


def cross_fitted_log_ratios(
    z: FloatArray,
    chain: np.ndarray,
    held_out: Sequence[np.ndarray],
    fit: Callable[
        [FloatArray, np.ndarray], tuple[Sequence[ExponentialFamily], FloatArray]
    ],
) -> FloatArray:
    """``log(sum_k pi_k q_k / p0)`` of each particle, (n,), by a fit not seeing it.

    Parameters
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Each particle's chain.
    held_out : sequence of ndarray of bool, shape (n,)
        Disjoint masks covering every particle, fitted in this order: each
        part is scored under ``fit`` of the particles outside it.
    fit : callable
        ``fit(points, point_chain) -> (components, weights)``, shifts of one
        structure and their weights ``pi_k``.
    """
    log_ratios = np.empty(len(z))
    for test in held_out:
        components, weights = fit(z[~test], chain[~test])
        log_joint = np.log(weights) + log_ratios_to_base(components, z[test])
        log_ratios[test] = logsumexp(log_joint, axis=1)
    return log_ratios


def held_out_weights(
    z: FloatArray,
    chain: np.ndarray,
    fitter: Fitter,
    base: ExponentialFamily,
    defensive: float,
    rng: np.random.Generator,
) -> HeldOutWeights:
    """The particles' weights ``p0 / q`` under fits that did not see them.

    The chains are dealt into ``PREDICTION_FOLDS`` folds; each fold's
    particles are weighed under the proposal fitted (by ``fitter``, the
    chosen fit, with the light regions of all the particles as the final
    proposal has them) to the other folds. Each fit sees 90% of the chains,
    so it is nearly the final fit's equal even in hundreds of dimensions (a
    fit to half of them overstated the final sample's variance there). The
    particles follow ``P0(. | f <= gamma)``, so their weights say, region by
    region, how the importance sample will fare (:class:`HeldOutWeights`).

    Parameters
    ----------
    z : ndarray of shape (n, D)
        The particles in standard-normal space.
    chain : ndarray of int, shape (n,)
        Each particle's chain.
    fitter : callable
        ``fitter(points, point_chain) -> (components, weights, shifted)``.
    base : ExponentialFamily
    defensive : float
        The proposal's share of ``P0``, in [0, 1).
    rng : numpy.random.Generator
        For the fits' seeding.

    Returns
    -------
    HeldOutWeights
        NaN in both fields with fewer than ``PREDICTION_FOLDS`` chains.
    """
    chains = np.unique(chain)
    if len(chains) < PREDICTION_FOLDS:
        return HeldOutWeights(float("nan"), float("nan"))
    fold = np.searchsorted(chains, chain) % PREDICTION_FOLDS
    log_ratios = cross_fitted_log_ratios(  # log(sum_k pi_k q_k / p0), (n,)
        z,
        chain,
        [fold == k for k in range(PREDICTION_FOLDS)],
        lambda p, c: with_light_regions(z, *fitter(p, c), base, rng),
    )
    if defensive > 0:
        log_ratios = np.logaddexp(
            math.log(defensive), math.log1p(-defensive) + log_ratios
        )
    w = np.exp(-log_ratios)
    covered = w < 1.0
    return HeldOutWeights(
        uncovered=float(np.mean(~covered)),
        covered_mean_weight=float(np.mean(np.where(covered, w, 0.0))),
    )
