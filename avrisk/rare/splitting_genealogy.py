"""Subset simulation's error from its particles' family tree.

Au & Beck's coefficient of variation (*Standard error* in
:mod:`avrisk.rare.splitting_levels`) sums the levels' errors as if the levels
were independent. They are not: every particle of a set descends from one
survivor of each set before it, and what a pinch decides -- how many of a
set's survivors happen to lie in the region that leads to ``gamma`` -- is
carried by all of their descendants. Where the event is reached through a
region that held a few of some set's survivors (a second failure region, a
decoy that draws most of the particles away), the answer is off by their
number's relative error, in every later level at once, and the summed
levels' error does not see it.

The family tree does. In set ``k`` (``k >= 1``) every chain starts from one
survivor of set ``k - 1``, and all particles of the last set carry the same
weight, so ``p_hat`` is a constant times ``sum_s H_s``, ``H_s`` the hits at
the threshold among the descendants of chain ``s`` of set ``k``. Given the
survivors of set ``k - 1`` the chains evolve independently (the levels
taken as fixed, as Au & Beck take them), so the spread of ``H_s`` over the
``n`` chains estimates the error of every factor from set ``k`` on,
correlation between levels included:

    cov_k^2 = n / (n - 1) sum_s (H_s - mean H)^2 / (sum_s H_s)^2
              + sum_{l < k} delta_l^2,

the factors before set ``k`` by their own ``delta_l^2``. The effective number
of chains the hits descend from, ``(sum_s H_s)^2 / sum_s H_s^2``, says how
many independent pieces of evidence that spread rests on. A spread of
``a`` families is known as a variance estimated from ``a`` draws is: the
interval normal on ``log p`` takes Student's t quantile with ``a - 1``
degrees of freedom (at least 1) instead of the normal one, as cluster-robust
errors of few clusters do, and the replicates' mean takes Welch and
Satterthwaite's degrees of freedom. With many families this changes little
(t at 30 degrees of freedom is 4% above the normal quantile); with fewer
than two the hits are in effect one family, and t at one degree of freedom
(12.7) gives the interval that says so. Set 0's draws are
independent, each its own cluster (``k = 0``, every factor), unless the first
set grew on a plateau (*Plateaus*), whose first draws are not counted. This
is the idea of Lee & Whiteley's (2018) and Du & Guyader's (2021) variance
estimators of sequential Monte Carlo, which count the descendants of each
particle at an earlier time. Clusters far back share few ancestors and their
spread is noisy; close ones miss the earlier pinches. The error used is
the one of the widest interval, Au & Beck's (normal) or any ``cov_k^2``
(with its t): it errs wide, never narrower than the sum over levels.

References
----------
A. Lee, N. Whiteley. "Variance estimation in the particle filter."
Biometrika 105, 2018.
Q. Du, A. Guyader. "Variance estimation in adaptive sequential Monte Carlo."
Annals of Applied Probability 31, 2021.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy import stats

from avrisk.rare.families.base import FloatArray
from avrisk.rare.final_stage import CONFIDENCE


class FamilyTreeError(NamedTuple):
    """What the family tree says of ``p_hat``'s error.

    Attributes
    ----------
    cov_squared : float
        ``cov_k^2`` of the set ``k`` whose interval is the widest (0 with no
        hit or no set of two clusters).
    dof : float
        Its degrees of freedom, ``max(1, a_k - 1)`` (``inf`` with none).
    ancestors : float
        The fewest effective chains (or set-0 draws) the hits descend from,
        over the same sets (``inf`` where none was looked at).
    """

    cov_squared: float
    dof: float
    ancestors: float

    def half_width(self) -> float:
        """Half the width of its interval on ``log p``."""
        return interval_quantile(self.dof) * math.sqrt(math.log1p(self.cov_squared))


def interval_quantile(dof: float) -> float:
    """The intervals' quantile: Student's t with ``dof``, normal for ``inf``."""
    level = 0.5 + CONFIDENCE / 2
    if math.isinf(dof):
        return float(stats.norm.ppf(level))
    return float(stats.t.ppf(level, dof))


def satterthwaite_dof(variances: Sequence[float], dofs: Sequence[float]) -> float:
    """Welch and Satterthwaite's degrees of freedom of a sum of variances.

    ``(sum v)^2 / sum(v^2 / dof)``; ``inf`` where every ``dof`` is (or every
    variance is 0).
    """
    denominator = sum(v * v / d for v, d in zip(variances, dofs, strict=True))
    return sum(variances) ** 2 / denominator if denominator > 0 else math.inf


def family_tree_error(
    sets: Sequence[tuple[FloatArray, float, int]],
    hits: FloatArray,
    level_cov: Sequence[float],
) -> FamilyTreeError:
    """The largest squared c.o.v. of ``p_hat`` over the family tree's clusters.

    Parameters
    ----------
    sets : sequence of (values, level, counted_from)
        The sets up to and including the one whose hits estimate ``p``:
        ``f`` by chain (shape (n_chains, max_length), NaN past each chain's
        end), the level below which its particles seeded the next set's
        chains (in the order of the flat, chain-after-chain values), and the
        first chain its factor counts (:class:`ParticleSet`).
    hits : ndarray of bool, shape (n_last,)
        Which particles of the last set (flat order) are at or below the
        threshold.
    level_cov : sequence of float
        Au & Beck's squared c.o.v. of each set's factor but the last.

    Returns
    -------
    FamilyTreeError
        The widest interval's ``cov_k^2`` and degrees of freedom and the
        fewest effective ancestors, over the sets ``k`` that have at least
        two clusters.
    """
    total = int(np.count_nonzero(hits))
    best, fewest = FamilyTreeError(0.0, math.inf, math.inf), math.inf
    if total == 0:
        return best
    # ancestor[i]: the chain of set k (or draw of set 0) particle i descends from
    ancestor = np.arange(hits.size)
    for k in range(len(sets) - 1, -1, -1):
        values, _, counted_from = sets[k]
        chain_of = np.nonzero(~np.isnan(values))[0]  # flat order
        if k > 0:
            cluster = chain_of[ancestor]
            n_clusters = values.shape[0]
        elif counted_from == 0:
            cluster, n_clusters = ancestor, chain_of.size
        else:
            break
        if n_clusters > 1:
            counts = np.bincount(cluster[hits], minlength=n_clusters)
            squares = np.sum((counts - counts.mean()) ** 2)
            spread = n_clusters / (n_clusters - 1) * squares
            families = total**2 / float(np.sum(counts**2))
            cov_squared = spread / total**2 + sum(level_cov[:k])
            here = FamilyTreeError(cov_squared, max(1.0, families - 1), families)
            best = max(best, here, key=FamilyTreeError.half_width)
            fewest = min(fewest, families)
        if k > 0:  # chain s of set k started from the s-th survivor of set k-1
            previous, level, _ = sets[k - 1]
            flat = previous[~np.isnan(previous)]
            ancestor = np.flatnonzero(flat <= level)[cluster]
    return best._replace(ancestors=fewest)
