"""How typical a rollout's start and drivers are under P0, as two percentiles.

``log p0`` of a whole situation says little to a person: with learned
drivers, 404 of its coordinates are the driver network's weights ``xi``, and
in that many dimensions the density is dominated by how far ``xi`` is from its
mean. The mode is then not typical: nearly every draw of P0 is far less
likely than it, so a failure near the mode reads "more likely than 100% of
P0", which is no statement about realism. P0 is a product of independent
blocks (:func:`avrisk.scenario.build_base_distribution`), so each part is read
on its own:

* the *initial situation*: the vehicles' positions, headings and speeds
  (four scaled-Beta coordinates per vehicle). Its percentile is the share of
  ``SITUATION_REFERENCE`` seeded draws of these blocks of P0 whose
  log-density is lower: 50 is a typical start, 1 a start as unusual as the
  least likely 1% of P0's;
* the *drivers*: the learned drivers' ``xi`` (and their action noise when it
  is part of ``X``), normal blocks. For a normal ``N(mu, Sigma)`` in ``d``
  dimensions, ``log p = log p(mu) - Q / 2`` with ``Q ~ chi2(d)``, so the
  share of P0's drivers with a lower density is exact:
  ``chi2.sf(2 (log p(mu) - log p), d)``. Absent without learned drivers.

A failure is ranked by the lower of its percentiles (as realistic as its
least typical part), ties by ``log p0``; :meth:`Typicality.rank` gives the
key, which the failures recorded during a run (:class:`FailureRecorder`) and
the report share.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from avrisk.assembly.parts import base_distribution
from avrisk.rare import FixedCovNormal, Product
from avrisk.scenario import ScenarioSpec
from avrisk.scenario.params import ParamLayout

FloatArray = NDArray[np.float64]

#: Draws of the initial situation's blocks of P0 its percentile is read among.
SITUATION_REFERENCE = 10_000


class Percentiles(NamedTuple):
    """Percentiles in [0, 100] of rows' two parts under P0 (module docstring).

    Attributes
    ----------
    situation : ndarray of shape (n,)
        Share [%] of P0's initial situations with a lower density.
    drivers : ndarray of shape (n,) or None
        Share [%] of P0's drivers with a lower density (None: no learned
        drivers).
    """

    situation: FloatArray
    drivers: FloatArray | None


class Typicality:
    """Reads rows of ``X`` as the percentiles of their start and their drivers.

    Parameters
    ----------
    base : Product
        The scenario's P0 (:func:`avrisk.assembly.base_distribution`).
    columns : sequence of str
        Names of its leading coordinates that make the initial situation
        (the vehicles' ``4 A``); the blocks after them must be normal (the
        drivers).
    n_reference : int, default=SITUATION_REFERENCE
        Draws of the situation's blocks to read its percentile among.
    seed : int, default=0
        Seed of those draws (the percentiles and the ranking are
        deterministic).

    Examples
    --------
    >>> from avrisk.rare import ScaledBeta
    >>> base = Product([ScaledBeta(2, 2, lo=0, scale=1),
    ...                 FixedCovNormal(np.zeros(3), cov=np.eye(3))])
    >>> typical = Typicality(base, ["veh0.s"])
    >>> x = np.array([[0.5, 0.0, 0.0, 0.0]])  # both parts at their mode
    >>> [float(p[0]) for p in typical.percentiles(x[:, :1], base.log_prob(x))]
    [100.0, 100.0]
    """

    def __init__(
        self,
        base: Product,
        columns: Sequence[str],
        n_reference: int = SITUATION_REFERENCE,
        seed: int = 0,
    ) -> None:
        self.columns = tuple(columns)
        self.n_situation = len(self.columns)
        cuts = np.cumsum([b.dim for b in base.blocks])
        if self.n_situation not in cuts:
            raise ValueError(f"no block of P0 ends at coordinate {self.n_situation}")
        k = int(np.searchsorted(cuts, self.n_situation)) + 1
        self.situation = Product(base.blocks[:k])
        drivers = base.blocks[k:]
        if not all(isinstance(b, FixedCovNormal) for b in drivers):
            raise TypeError("the blocks after the initial situation must be normal")
        self.drivers_dim = sum(b.dim for b in drivers)
        #: log-density of the drivers' blocks at their mean (their mode)
        self.drivers_mode = sum(float(b.log_prob(b.mean[None])[0]) for b in drivers)
        rng = np.random.default_rng(seed)
        self.reference = np.sort(
            self.situation.log_prob(self.situation.sample(n_reference, rng))
        )

    def percentiles(self, situation: FloatArray, log_p0: FloatArray) -> Percentiles:
        """The percentiles of rows from their situation's columns and ``log p0``.

        Parameters
        ----------
        situation : ndarray of shape (n, n_situation)
            The rows' first ``n_situation`` coordinates.
        log_p0 : ndarray of shape (n,)
            The rows' log-density under the whole of P0 (the drivers' part is
            what it holds beyond the situation's).
        """
        own = self.situation.log_prob(np.asarray(situation, dtype=np.float64))
        below = np.searchsorted(self.reference, own, side="left")
        share = 100.0 * below / self.reference.size
        if not self.drivers_dim:
            return Percentiles(share, None)
        q = np.maximum(2.0 * (self.drivers_mode - (np.asarray(log_p0) - own)), 0.0)
        return Percentiles(share, 100.0 * stats.chi2.sf(q, self.drivers_dim))

    def rank(self, situation: FloatArray, log_p0: FloatArray) -> FloatArray:
        """Keys of the failures' ranking, the most realistic highest.

        Returns
        -------
        ndarray of shape (n, 2)
            Per row: the lower of its percentiles, then ``log p0`` (which
            orders rows whose lower percentile ties, e.g. starts less likely
            than every reference draw); compared row by row, lexicographically.
        """
        share = self.percentiles(situation, log_p0)
        lowest = share.situation if share.drivers is None else np.minimum(*share)
        return np.stack([lowest, np.asarray(log_p0, dtype=np.float64)], axis=1)


def scenario_typicality(spec: ScenarioSpec) -> Typicality:
    """:class:`Typicality` of a scenario's P0: its vehicles make the situation."""
    return Typicality(base_distribution(spec), ParamLayout(spec.n_vehicles).columns)
