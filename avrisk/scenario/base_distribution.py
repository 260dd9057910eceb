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
``Sigma0^-1`` of the shipped driver model (:func:`xi_base_family`), which the
caller passes in (:func:`avrisk.assembly.base_distribution` passes the shipped
one); and, when the drivers' action noise is part of ``X``
(``actions: sampled_in_x``), its innovations (:func:`noise_base_family`)::

    noise ~ N(0, I)                      in R^(2 T C), one per driver, step, action
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from avrisk.rare import ExponentialFamily, FixedCovNormal, Product, ScaledBeta
from avrisk.scenario.params import ParamLayout
from avrisk.scenario.scene import VEHICLE_FIELDS, MarginalSpec
from avrisk.scenario.spec import ScenarioSpec


class NormalPrior(Protocol):
    """A normal distribution by its mean and precision (e.g. ``XiPrior``)."""

    @property
    def mean(self) -> NDArray[np.float64]:
        """Mean, shape (d,)."""
        ...

    @property
    def precision(self) -> Any:
        """Inverse covariance, (d, d), symmetric positive definite; may be sparse."""
        ...


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
    prior: NormalPrior,
    *,
    max_shift: float | None = 0.01,
    unit: Literal["absolute", "prior_sd"] = "absolute",
) -> FixedCovNormal:
    """The ``xi`` block of ``P0`` with its sparse precision.

    Parameters
    ----------
    prior : NormalPrior
        ``N(mu0, Sigma0)``, e.g. the shipped
        :func:`avrisk.agents.drivers.load_xi_prior`.
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
        Dimension ``len(prior.mean)`` (404 for the shipped driver network);
        the precision is kept sparse; samples are rounded to float32 (the
        precision of the simulator's network).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from scipy import sparse
    >>> prior = SimpleNamespace(mean=np.zeros(3), precision=sparse.eye_array(3))
    >>> fam = xi_base_family(prior)
    >>> fam.dim, fam.sample(2, np.random.default_rng(0)).shape
    (3, (2, 3))
    """
    if unit not in ("absolute", "prior_sd"):
        raise ValueError(f"unit must be 'absolute' or 'prior_sd'; got {unit!r}")
    # The simulator reads xi in float32: float32 samples change no rollout and
    # halve the xi columns of a run's samples table (404 of its 428 columns).
    family = FixedCovNormal(prior.mean, precision=prior.precision, float32_samples=True)
    if max_shift is not None and unit == "prior_sd":
        max_shift = max_shift * family.std
    return family.with_max_shift(max_shift)


def noise_base_family(dim: int) -> FixedCovNormal:
    """The learned drivers' action innovations: ``N(0, I)`` in ``dim`` dimensions.

    Its cross-entropy search box is the single point 0 (CE leaves the block
    at ``P0``: a mean update in ``2 T C`` dimensions is noise); samples are
    rounded to float32, the precision the drivers read them in.

    Parameters
    ----------
    dim : int
        ``2 T C`` (:attr:`~avrisk.scenario.spec.ScenarioSpec.noise_dim`).

    Returns
    -------
    avrisk.rare.FixedCovNormal

    Examples
    --------
    >>> fam = noise_base_family(4)
    >>> fam.dim, bool(fam.searched_coordinates().any())
    (4, False)
    """
    return FixedCovNormal(
        np.zeros(dim),
        precision=sparse.eye_array(dim, format="csr"),
        max_shift=0.0,
        float32_samples=True,
    )


def build_base_distribution(
    spec: ScenarioSpec, xi_prior: NormalPrior | None = None
) -> Product:
    """Build ``P0`` for a scenario.

    Parameters
    ----------
    spec : ScenarioSpec
    xi_prior : NormalPrior or None
        ``N(mu0, Sigma0)`` of the learned drivers' ``xi``; required when the
        scenario has learned drivers, unused otherwise.

    Returns
    -------
    avrisk.rare.Product
        ``4 A`` one-dimensional :class:`~avrisk.rare.ScaledBeta` blocks in the
        column order of ``ParamLayout.from_spec(spec)``, then, if the scenario
        has learned drivers, the 404-dimensional :func:`xi_base_family` with
        the search box of ``spec.learned_drivers``, then, if their action
        noise is in ``X``, :func:`noise_base_family`;
        ``dim == layout.dim``. ``sample(n, rng)`` gives ``X`` of shape (n, D);
        ``log_prob(X)`` gives ``log p0`` of shape (n,) [log of 1 / (m m deg
        m/s) per vehicle, plus the log-density of ``xi``].

    Raises
    ------
    ValueError
        If the scenario has learned drivers and ``xi_prior`` is None.

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
    xi_dim = None
    if spec.has_learned_drivers:
        if xi_prior is None:
            raise ValueError(
                f"scenario {spec.name!r} has learned drivers: pass xi_prior, the "
                "distribution of their xi (avrisk.assembly.base_distribution does)"
            )
        search = spec.learned_drivers
        xi = xi_base_family(
            xi_prior, max_shift=search.xi_search, unit=search.xi_search_unit
        )
        blocks.append(xi)
        xi_dim = xi.dim
        if spec.noise_dim:
            blocks.append(noise_base_family(spec.noise_dim))
    p0 = Product(blocks)
    layout = ParamLayout.from_spec(spec, xi_dim)
    if p0.dim != layout.dim:  # pragma: no cover - guards the two orderings
        raise AssertionError(f"P0 has dim {p0.dim}, layout has {layout.dim}")
    return p0
