"""Generated families of rare-event problems with exact answers.

* :func:`k_region_problem` -- ``k`` half-space failure regions of unequal mass
  with orthogonal normals in ``d`` dimensions (several mechanisms, one rare).
* :func:`plateau_problem` -- ``f`` constant (a tie) on 90% to 99.99% of ``P0``
  and continuous elsewhere, as a capped time-to-collision is when nothing
  closes.
* :func:`decoy_problem` -- a common mechanism of low ``f`` that never ends in
  the event (a near miss), beside the rare one that does, as the ego's
  close following beside the corner of ``P0`` that ends in a crash.
* :func:`beta_product_problem`, :func:`beta_pair_product_problem` -- blocks of
  the engine's :class:`~avrisk.rare.ScaledBeta` family.

Each takes its parameters (dimension, ``p``) as arguments, so a benchmark
names a point of the family (:func:`avrisk.testing.suite.suite_problem`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

from avrisk.rare import Product, ScaledBeta
from avrisk.rare.families.base import FloatArray
from avrisk.testing.exact import quad, standard_normal, union_probability
from avrisk.testing.problems import AnalyticProblem

__all__ = [
    "DIRECTIONS_SEED",
    "PLATEAU_CAP",
    "beta_pair_product_problem",
    "beta_product_problem",
    "decoy_problem",
    "directions",
    "k_region_problem",
    "plateau_problem",
]

#: Seed of the orthonormal directions of the generated families: part of the
#: problem's definition, not of a run.
DIRECTIONS_SEED = 46


def directions(dim: int, k: int) -> FloatArray:
    """``k`` orthonormal directions in ``R^dim``, shape (k, dim), fixed by the seed."""
    if k > dim:
        raise ValueError(f"{k} orthogonal directions need dim >= {k}; got {dim}")
    rng = np.random.default_rng(DIRECTIONS_SEED)
    q, _ = np.linalg.qr(rng.standard_normal((dim, k)))
    return q.T.copy()


def k_region_problem(
    k: int, dim: int, p: float = 1e-6, ratio: float = 0.5
) -> AnalyticProblem:
    """``k`` half-space failure regions of unequal mass in ``N(0, I_dim)``.

    Region ``i`` is ``{a_i . x >= beta_i}`` with orthonormal ``a_1..a_k``
    (shape (k, dim), a fixed random rotation, so no method gains from the
    coordinate axes), and ``f(x) = min_i (beta_i - a_i . x)``, ``gamma = 0``.
    The regions' masses ``p_i = Phi(-beta_i)`` fall geometrically,
    ``p_i proportional to ratio^(i-1)``, scaled so that the union has
    probability ``p``; the regions are independent events (orthogonal
    normals), so exactly

        p = 1 - prod_i (1 - Phi(-beta_i)).

    Parameters
    ----------
    k : int
        Number of regions, ``1 <= k <= dim``.
    dim : int
        Dimension ``d``.
    p : float
        Target probability of the union (``p_exact`` is the closed form at the
        solved ``beta_i``, equal to ``p`` to solver precision).
    ratio : float
        Mass of region ``i + 1`` over that of region ``i``, in (0, 1].
    """
    if not (1 <= k <= dim and 0.0 < p < 1.0 and 0.0 < ratio <= 1.0):
        raise ValueError(f"need 1 <= k <= dim, 0 < p < 1, 0 < ratio <= 1; got {k}")
    shares = ratio ** np.arange(k)
    shares = shares / shares.sum()
    scale = optimize.brentq(
        lambda s: union_probability(np.minimum(s * shares, 1 - 1e-16)) - p,
        p / 10,
        1.0 / shares.max(),
        xtol=1e-300,
        rtol=1e-15,
    )
    betas = stats.norm.isf(scale * shares)
    normals = directions(dim, k)

    def f(x: FloatArray) -> FloatArray:
        return np.min(betas[None, :] - x @ normals.T, axis=1)

    p_exact = union_probability(stats.norm.sf(betas))
    return AnalyticProblem(
        f"kregions_k{k}_d{dim}_p{p:.0e}",
        standard_normal(dim),
        f,
        0.0,
        p_exact,
        reference=f"closed form, 1 - prod(1 - Phi(-beta_i)), beta = "
        f"{', '.join(f'{b:.4f}' for b in betas)}",
    )


#: The value of ``f`` on the plateau (a capped time-to-collision's cap).
PLATEAU_CAP = 1.0


def plateau_problem(
    share: float, p: float = 1e-6, dim: int = 10, kind: str = "self"
) -> AnalyticProblem:
    """``f`` ties at ``PLATEAU_CAP`` on a share of ``P0``; continuous elsewhere.

    ``X ~ N(0, I_dim)``, ``a`` and ``b`` orthonormal (a fixed rotation),
    ``gamma = 0``.

    * ``kind="self"``: ``f = min(CAP, beta - a . x)``. The plateau is
      ``a . x <= beta - CAP``, of mass exactly ``share`` (``CAP = beta -
      Phi^-1(share)``); ``p = Phi(-beta)``.
    * ``kind="gate"``: the plateau is set by another coordinate, as when the
      other car does not close in: ``f = CAP`` where ``b . x < c`` and
      ``min(CAP, beta - a . x)`` elsewhere, with ``Phi(c) = share``. Then
      ``p = (1 - share) Phi(-beta)`` and the plateau's mass is ``share + (1 -
      share) Phi(beta - CAP)`` (a little more than ``share``).

    Parameters
    ----------
    share : float
        In (0, 1): the share of ``P0`` where ``f`` ties (``kind="self"``), or
        where the gate is shut (``kind="gate"``).
    p : float
        The event's probability; for ``"gate"`` below ``1 - share``.
    dim : int
        Dimension, at least 2.
    kind : {"self", "gate"}
    """
    if not (0.0 < share < 1.0 and dim >= 2):
        raise ValueError(f"need 0 < share < 1 and dim >= 2; got {share}, {dim}")
    a, b = directions(dim, 2)
    cap = PLATEAU_CAP
    if kind == "self":
        beta = float(stats.norm.isf(p))
        cap = beta - float(stats.norm.ppf(share))
        if cap <= 0:
            raise ValueError(f"share={share} leaves no plateau above p={p}")

        def f(x: FloatArray) -> FloatArray:
            return np.minimum(cap, beta - x @ a)

        p_exact = float(stats.norm.sf(beta))
        mass = share
    elif kind == "gate":
        if not p < 1.0 - share:
            raise ValueError(f"p={p} must be below 1 - share = {1 - share}")
        c = float(stats.norm.ppf(share))
        beta = float(stats.norm.isf(p / (1.0 - share)))

        def f(x: FloatArray) -> FloatArray:
            open_ = x @ b >= c
            return np.where(open_, np.minimum(cap, beta - x @ a), cap)

        p_exact = float(stats.norm.sf(c) * stats.norm.sf(beta))
        mass = share + (1.0 - share) * float(stats.norm.cdf(beta - cap))
    else:
        raise ValueError(f"kind must be 'self' or 'gate'; got {kind!r}")
    return AnalyticProblem(
        f"plateau_{kind}_m{share:g}_d{dim}_p{p:.0e}",
        standard_normal(dim),
        f,
        0.0,
        p_exact,
        reference=f"closed form; f ties at {cap:.4g} on {mass:.6g} of P0",
    )


#: Floor of the decoy mechanism's ``f`` (:func:`decoy_problem`): its near
#: misses come as close as this to the event, never closer.
DECOY_FLOOR = 0.5
#: Slope of the true mechanism's ``f`` per standard deviation of ``P0``.
DECOY_SLOPE = 1.33


def decoy_problem(share: float, p: float = 1e-6, dim: int = 10) -> AnalyticProblem:
    """A rare mechanism that ends in the event beside a common one that does not.

    ``X ~ N(0, I_dim)``, ``a`` and ``b`` orthonormal (a fixed rotation),
    ``gamma = 0``, ``f = min(f_T, f_D)``:

    * the true mechanism ``f_T = s (beta - a . x)``, ``s = DECOY_SLOPE``, so
      ``p = Phi(-beta)``;
    * the decoy ``f_D = FLOOR + exp(s_D (c - b . x))``, ``FLOOR =
      DECOY_FLOOR``: its values crowd down to ``FLOOR > 0`` and never reach
      the event.

    ``c`` and ``s_D`` are set so that the true mechanism holds ``share`` of
    ``P0(f <= 1)`` (the two overlap by the product of their masses) and the
    two hold equal mass of ``P0(f <= 0.6)``. Levels
    of subset simulation above ``f = 1`` hold ``p0 N`` survivors, about
    ``share p0 N`` of them in the true mechanism; chains do not cross between
    the two, so a run that loses those few follows the decoy down to its
    floor and runs out of levels (a near-miss mechanism of a scenario).

    Parameters
    ----------
    share : float
        In (0, 1): the true mechanism's share of ``P0(f <= 1)``.
    p : float
        The event's probability.
    dim : int
        Dimension, at least 2.
    """
    if not (0.0 < share < 1.0 and dim >= 2):
        raise ValueError(f"need 0 < share < 1 and dim >= 2; got {share}, {dim}")
    a, b = directions(dim, 2)
    beta, s = float(stats.norm.isf(p)), DECOY_SLOPE
    at_one = float(stats.norm.sf(beta - 1.0 / s))  # P0(f_T <= 1)
    at_06 = float(stats.norm.sf(beta - 0.6 / s))  # P0(f_T <= 0.6)
    # P0(f_D <= l) = Phi(log(l - FLOOR) / s_D - c): solve at l = 1 and l = 0.6
    z_one = stats.norm.isf(at_one * (1.0 - share) / share)  # P0(f_D <= 1)
    z_06 = stats.norm.isf(at_06)
    s_d = (math.log(1.0 - DECOY_FLOOR) - math.log(0.6 - DECOY_FLOOR)) / (z_06 - z_one)
    c = float(z_one + math.log(1.0 - DECOY_FLOOR) / s_d)

    def f(x: FloatArray) -> FloatArray:
        decoy = DECOY_FLOOR + np.exp(s_d * (c - x @ b))
        return np.minimum(s * (beta - x @ a), decoy)

    return AnalyticProblem(
        f"decoy_s{share:g}_d{dim}_p{p:.0e}",
        standard_normal(dim),
        f,
        0.0,
        float(stats.norm.sf(beta)),
        reference=f"closed form; a decoy holding {1 - share:.3g} of P0(f <= 1) "
        f"never falls below {DECOY_FLOOR}",
    )


def beta_product_problem(
    k: int = 4, p: float = 1e-6, a: float = 2.0
) -> AnalyticProblem:
    """The product of ``k`` i.i.d. ``Beta(a, 1)`` below a threshold ``t``.

    Each block is the engine's ``ScaledBeta(a, 1)`` on ``[0, 1]``. Since
    ``-log U ~ Exponential(a)`` for ``U ~ Beta(a, 1)``, ``-log prod U_i ~
    Gamma(k, rate a)`` and

        p = P(prod U_i <= t) = Gamma(k, a).sf(-log t),

    closed form; ``t`` is solved so that ``p`` is the target. ``f(x) = sum_i
    log x_i``, ``gamma = log t`` (the log of the product, so that ``f`` keeps
    its precision near 0).
    """
    log_t = -float(stats.gamma.isf(p, k, scale=1.0 / a))
    base = Product([ScaledBeta(a, 1.0, bounds=(0.5, 7.0)) for _ in range(k)])

    def f(x: FloatArray) -> FloatArray:
        with np.errstate(divide="ignore"):
            return np.log(x).sum(axis=1)

    p_exact = float(stats.gamma.sf(-log_t, k, scale=1.0 / a))
    return AnalyticProblem(
        f"beta_product_k{k}_p{p:.0e}",
        base,
        f,
        log_t,
        p_exact,
        reference="closed form, the Gamma(k, a) tail of -log of the product",
    )


def _beta22_cdf(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def beta_pair_product_problem(p: float = 1e-6) -> AnalyticProblem:
    """Two ``Beta(2, 2)`` (``ScaledBeta`` on ``[0, 1]``) with product below ``t``.

    With ``F(x) = 3 x^2 - 2 x^3`` the ``Beta(2, 2)`` distribution function,

        p = P(U_1 U_2 <= t) = int_0^1 6 u (1 - u) F(min(1, t / u)) du,

    by quadrature split at ``u = t`` (relative error about 1e-12); ``t`` is
    solved so that ``p`` is the target. ``f(x) = x_1 x_2``, ``gamma = t``.
    """

    def cdf(t: float) -> float:
        head = _beta22_cdf(t)  # u <= t: F(t/u) = 1
        tail = quad(lambda u: 6 * u * (1 - u) * _beta22_cdf(t / u), t, 1.0)
        return head + tail

    t = float(
        optimize.brentq(
            lambda s: math.log(cdf(s)) - math.log(p),
            1e-12,
            0.5,
            xtol=1e-300,
            rtol=1e-14,
        )
    )
    base = Product([ScaledBeta(2.0, 2.0) for _ in range(2)])

    def f(x: FloatArray) -> FloatArray:
        return x[:, 0] * x[:, 1]

    return AnalyticProblem(
        f"beta_pair_product_p{p:.0e}",
        base,
        f,
        t,
        cdf(t),
        reference="quadrature of the Beta(2, 2) distribution function",
    )
