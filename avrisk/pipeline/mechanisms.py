"""``p`` decomposed by what happened: each label's share, with an interval.

An estimate of ``p = P0(f <= gamma)`` from a final stage of weighted samples
(naive Monte Carlo: weight 1; importance sampling: ``w = p0 / q``) is the mean
of ``w 1{f <= gamma}``. A per-sample label (for the simulator: how the ego met
the other vehicle) splits it exactly into ``p = sum_c p_c`` with ``p_c =
mean(w 1{f <= gamma, label = c})``, each with its own standard error. A label
whose share an estimator under-samples shows at once. Samples whose
evaluation failed count in no label (they are safe in ``p``).

Only estimators whose estimate is such a final-stage mean are decomposed
(:attr:`Estimator.decomposable`); splitting estimates are products over levels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from avrisk.rare.final_stage import BINOMIAL_INTERVALS, CONFIDENCE
from avrisk.rare.intervals import normal_interval

__all__ = ["decompose"]


def decompose(
    f: np.ndarray,
    weight: np.ndarray,
    labels: np.ndarray,
    names: Mapping[int, str],
    thresholds: Sequence[float],
    *,
    weighted: bool,
    failed: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """Per threshold, ``p`` of each label, its standard error, interval and hits.

    Parameters
    ----------
    f, weight, labels : ndarray of shape (n,)
        The final stage's values, weights and integer labels.
    names : mapping of int to str
        The label of each code (codes not named are ``"code N"``).
    thresholds : sequence of float
    weighted : bool
        Importance weights (normal interval) or naive sampling (weight 1,
        exact binomial interval).
    failed : ndarray of bool, shape (n,), optional
        Samples whose evaluation failed (in no label).

    Returns
    -------
    list of dict
        One per threshold: ``gamma`` and ``by_label``, a list of ``{label,
        code, p, stderr, ci, n_hits, share}`` (``share`` of the threshold's
        ``p``), in code order.

    Examples
    --------
    >>> f = np.array([0.0, 0.0, 1.0, 5.0])
    >>> out = decompose(f, np.ones(4), np.array([1, 2, 1, 0]), {1: "a", 2: "b"},
    ...                 [0.5], weighted=False)
    >>> [(d["label"], d["p"], d["share"]) for d in out[0]["by_label"]]
    [('a', 0.25, 0.5), ('b', 0.25, 0.5)]
    """
    n = f.size
    ok = np.ones(n, dtype=bool) if failed is None else ~failed
    out = []
    for g in thresholds:
        hit = ok & (f <= g)
        total = float(np.sum(weight * hit)) / n
        parts = []
        for code in np.unique(labels[hit]):
            mine = hit & (labels == code)
            term = weight * mine
            p = float(term.mean())
            k = int(mine.sum())
            if weighted:
                se = float(term.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0
                ci = normal_interval(p, se, CONFIDENCE)
            else:
                se = float(np.sqrt(p * (1 - p) / n))
                ci = BINOMIAL_INTERVALS["clopper-pearson"](k, n, CONFIDENCE)
            parts.append(
                {
                    "label": names.get(int(code), f"code {int(code)}"),
                    "code": int(code),
                    "p": p,
                    "stderr": se,
                    "ci": [float(ci[0]), float(ci[1])],
                    "n_hits": k,
                    "share": p / total if total > 0 else None,
                }
            )
        out.append({"gamma": float(g), "by_label": parts})
    return out
