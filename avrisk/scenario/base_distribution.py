"""The base distribution ``P0`` of a scenario, as a product of exponential families.

Each vehicle slot contributes four independent scaled-Beta coordinates
(paper, Sec. 5)::

    S_j ~ scale_s Beta(a, b) + lo_s      along the road, relative to the slot [m]
    T_j ~ scale_t Beta(a, b) + lo_t      from the lane centre [m]
    W_j ~ scale_w Beta(a, b) + lo_w      from the lane heading [deg]
    V_j ~ scale_v Beta(a, b) + lo_v      initial speed [m/s]

in the column order of :class:`avrisk.scenario.params.ParamLayout`. A scenario
with learned drivers appends one more block, the driver network's last layer
(paper, Sec. 5 and appendix B)::

    xi ~ N(mu0, Sigma0)                  in R^404, one draw per rollout

with the ensemble mean ``mu0`` and the sparse graphical-lasso precision
``Sigma0^-1`` of the shipped driver model (:func:`xi_base_family`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from avrisk.rare import ExponentialFamily, FixedCovNormal, Product, ScaledBeta
from avrisk.scenario.params import ParamLayout
from avrisk.scenario.scene import VEHICLE_FIELDS, MarginalSpec
from avrisk.scenario.spec import ScenarioSpec

if TYPE_CHECKING:
    from avrisk.agents.drivers.store import XiPrior


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


def xi_base_family(
    prior: XiPrior | None = None,
    *,
    max_shift: float | None = 0.01,
    unit: Literal["absolute", "prior_sd"] = "absolute",
) -> FixedCovNormal:
    """The ``xi`` block of ``P0`` with its sparse precision.

    Parameters
    ----------
    prior : XiPrior, optional
        Default the shipped one (:func:`avrisk.agents.drivers.load_xi_prior`).
    max_shift : float or None, default=0.01
        CE search box half-width around ``mu0`` (paper: 0.01 absolute); None
        for no box.
    unit : {"absolute", "prior_sd"}, default="absolute"
        ``max_shift`` in the units of ``xi``, or in prior standard deviations
        ``sqrt(diag Sigma0)`` of each coordinate (one box that is equally
        tight for every coordinate; see
        :class:`~avrisk.scenario.components.LearnedDriversSpec`).

    Returns
    -------
    avrisk.rare.FixedCovNormal
        Dimension ``XI_DIM = 404``; the precision is kept sparse; samples are
        rounded to float32 (the precision of the simulator's network).

    Examples
    --------
    >>> import numpy as np
    >>> fam = xi_base_family()
    >>> fam.dim, fam.sample(2, np.random.default_rng(0)).shape
    (404, (2, 404))
    """
    if prior is None:
        # Imported here: the driver package needs torch (see ParamLayout.from_spec).
        from avrisk.agents.drivers.store import load_xi_prior

        prior = load_xi_prior()
    if unit not in ("absolute", "prior_sd"):
        raise ValueError(f"unit must be 'absolute' or 'prior_sd'; got {unit!r}")
    # The simulator reads xi in float32: float32 samples change no rollout and
    # halve the xi columns of a run's samples table (404 of its 428 columns).
    family = FixedCovNormal(prior.mean, precision=prior.precision, float32_samples=True)
    if max_shift is not None and unit == "prior_sd":
        max_shift = max_shift * family.std
    return family.with_max_shift(max_shift)


def build_base_distribution(spec: ScenarioSpec) -> Product:
    """Build ``P0`` for a scenario.

    Parameters
    ----------
    spec : ScenarioSpec

    Returns
    -------
    avrisk.rare.Product
        ``4 A`` one-dimensional :class:`~avrisk.rare.ScaledBeta` blocks in the
        column order of ``ParamLayout.from_spec(spec)``, then, if the scenario
        has learned drivers, the 404-dimensional :func:`xi_base_family` with
        the search box of ``spec.learned_drivers``;
        ``dim == layout.dim``. ``sample(n, rng)`` gives ``X`` of shape (n, D);
        ``log_prob(X)`` gives ``log p0`` of shape (n,) [log of 1 / (m m deg
        m/s) per vehicle, plus the log-density of ``xi``].

    Examples
    --------
    >>> import numpy as np
    >>> from avrisk.scenario import load_spec
    >>> p0 = build_base_distribution(load_spec("highway_idm"))
    >>> p0.dim
    24
    >>> p0.sample(3, np.random.default_rng(0)).shape
    (3, 24)
    """
    blocks: list[ExponentialFamily] = [
        marginal_family(getattr(spec.initial_for(j), name))
        for j in range(spec.n_vehicles)
        for name in VEHICLE_FIELDS
    ]
    if spec.has_learned_drivers:
        search = spec.learned_drivers
        blocks.append(
            xi_base_family(max_shift=search.xi_search, unit=search.xi_search_unit)
        )
    p0 = Product(blocks)
    layout = ParamLayout.from_spec(spec)
    if p0.dim != layout.dim:  # pragma: no cover - guards the two orderings
        raise AssertionError(f"P0 has dim {p0.dim}, layout has {layout.dim}")
    return p0
