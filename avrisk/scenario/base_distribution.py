"""The base distribution ``P0`` of a scenario, as a product of exponential families.

Each vehicle slot contributes four independent scaled-Beta coordinates
(paper, Sec. 5)::

    S_j ~ scale_s Beta(a, b) + lo_s      along the road, relative to the slot [m]
    T_j ~ scale_t Beta(a, b) + lo_t      from the lane centre [m]
    W_j ~ scale_w Beta(a, b) + lo_w      from the lane heading [deg]
    V_j ~ scale_v Beta(a, b) + lo_v      initial speed [m/s]

in the column order of :class:`avrisk.scenario.params.ParamLayout`. The
learned-driver block ``xi ~ N(mu0, Sigma0)`` will be appended as one more block
of the product when learned drivers land.
"""

from __future__ import annotations

from avrisk.rare import Product, ScaledBeta
from avrisk.scenario.params import ParamLayout
from avrisk.scenario.spec import VEHICLE_FIELDS, MarginalSpec, ScenarioSpec


def marginal_family(marginal: MarginalSpec) -> ScaledBeta:
    """The scaled-Beta family of one marginal, with its CE search box.

    Parameters
    ----------
    marginal : MarginalSpec

    Returns
    -------
    avrisk.rare.ScaledBeta
        ``Beta(a, b)`` on ``[lo, lo + scale]``, search box ``marginal.search``.
    """
    return ScaledBeta(
        marginal.a,
        marginal.b,
        lo=marginal.lo,
        scale=marginal.scale,
        bounds=tuple(marginal.search),
    )


def build_base_distribution(spec: ScenarioSpec) -> Product:
    """Build ``P0`` for a scenario.

    Parameters
    ----------
    spec : ScenarioSpec

    Returns
    -------
    avrisk.rare.Product
        ``4 A`` one-dimensional :class:`~avrisk.rare.ScaledBeta` blocks in the
        column order of ``ParamLayout.from_spec(spec)``; ``dim == layout.dim``.
        ``sample(n, rng)`` gives ``X`` of shape (n, D); ``log_prob(X)`` gives
        ``log p0`` of shape (n,) [log of 1 / (m m deg m/s) per vehicle].

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.scenario import load_spec
    >>> p0 = build_base_distribution(load_spec("highway_default"))
    >>> p0.dim
    24
    >>> p0.sample(3, np.random.default_rng(0)).shape
    (3, 24)
    """
    blocks = [
        marginal_family(getattr(spec.initial_for(j), name))
        for j in range(spec.n_vehicles)
        for name in VEHICLE_FIELDS
    ]
    p0 = Product(blocks)
    layout = ParamLayout.from_spec(spec)
    if p0.dim != layout.dim:  # pragma: no cover - guards the two orderings
        raise AssertionError(f"P0 has dim {p0.dim}, layout has {layout.dim}")
    return p0
