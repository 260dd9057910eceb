"""``xi ~ N(mu0, Sigma0)`` as a block of the engine's base distribution.

The agents layer holds the fitted prior (:class:`avrisk.agents.drivers.XiPrior`)
but may not import the estimation engine; this module, which may, turns it
into the engine's :class:`~avrisk.rare.FixedCovNormal` with the paper's CE
search box ``||mu - mu0||_inf <= 0.01``.
"""

from __future__ import annotations

from avrisk.agents.drivers.store import XiPrior, load_xi_prior
from avrisk.rare import FixedCovNormal

__all__ = ["xi_base_family"]


def xi_base_family(
    prior: XiPrior | None = None, *, max_shift: float | None = 0.01
) -> FixedCovNormal:
    """The ``xi`` block of ``P0`` with its sparse precision.

    Parameters
    ----------
    prior : XiPrior, optional
        Default the shipped one (:func:`avrisk.agents.drivers.load_xi_prior`).
    max_shift : float or None, default=0.01
        CE search box half-width around ``mu0`` (paper); None for no box.

    Returns
    -------
    avrisk.rare.FixedCovNormal
        Dimension ``XI_DIM = 404``; the precision is kept sparse.

    Examples
    --------
    >>> import numpy as np
    >>> fam = xi_base_family()
    >>> fam.dim, fam.sample(2, np.random.default_rng(0)).shape
    (404, (2, 404))
    """
    prior = load_xi_prior() if prior is None else prior
    return FixedCovNormal(prior.mean, precision=prior.precision, max_shift=max_shift)
