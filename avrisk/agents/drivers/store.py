"""The shipped driver model: network weights and the distribution of ``xi``.

Two small files in ``avrisk/data/drivers/`` (written by
:func:`avrisk.learning.training.train.train_drivers`, read without pickle):

* ``driver_net.npz`` -- :class:`~avrisk.agents.drivers.network.DriverNet`
  weights (float32): trunk, input standardisation, action scale and the shared
  head (``default_xi``).
* ``xi_prior.npz`` -- :class:`XiPrior`: ``mu0`` (404,), the sparse precision
  ``Sigma0^-1`` (404, 404) in CSR form, the ``m`` ensemble heads it was fitted
  to, and the fit's metadata (JSON).

``xi ~ N(mu0, Sigma0)`` is the learned-driver block of the base distribution;
:func:`avrisk.scenario.xi_base_family` turns an :class:`XiPrior` into the
engine's ``FixedCovNormal`` (the agents layer does not import the engine).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.xi import XI_DIM

__all__ = [
    "DRIVER_NET_FILE",
    "XI_PRIOR_FILE",
    "XiPrior",
    "default_drivers_dir",
    "load_driver_net",
    "load_xi_prior",
]

DRIVER_NET_FILE = "driver_net.npz"
XI_PRIOR_FILE = "xi_prior.npz"


@dataclass(frozen=True)
class XiPrior:
    """``N(mu0, Sigma0)`` over the driver network's last layer.

    Attributes
    ----------
    mean : ndarray of shape (XI_DIM,)
        ``mu0``, the ensemble mean of the heads.
    precision : scipy.sparse.csr_array of shape (XI_DIM, XI_DIM)
        ``Sigma0^-1`` from the graphical lasso; symmetric positive definite.
    members : ndarray of shape (m, XI_DIM)
        The ensemble heads the prior was fitted to.
    meta : dict
        How it was fitted (alpha, shrinkage, sparsity, seed, ...).
    """

    mean: NDArray[np.float64]
    precision: sparse.csr_array
    members: NDArray[np.float64]
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mean.shape != (XI_DIM,):
            raise ValueError(f"mean must have shape ({XI_DIM},); got {self.mean.shape}")
        if self.precision.shape != (XI_DIM, XI_DIM):
            raise ValueError(
                f"precision must have shape ({XI_DIM}, {XI_DIM}); got "
                f"{self.precision.shape}"
            )
        if self.members.ndim != 2 or self.members.shape[1] != XI_DIM:
            raise ValueError(
                f"members must have shape (m, {XI_DIM}); got {self.members.shape}"
            )

    @property
    def sparsity(self) -> float:
        """Fraction of off-diagonal precision entries that are exactly zero."""
        d = XI_DIM
        off = self.precision.nnz - int(np.count_nonzero(self.precision.diagonal()))
        return 1.0 - off / (d * d - d)

    def save(self, path: str | Path) -> None:
        """Write an uncompressed ``.npz`` (no pickle)."""
        p = sparse.csr_array(self.precision)
        np.savez(
            Path(path),
            mean=self.mean,
            precision_data=p.data,
            precision_indices=p.indices.astype(np.int32),
            precision_indptr=p.indptr.astype(np.int32),
            members=self.members,
            meta=np.array(json.dumps(self.meta, sort_keys=True)),
        )

    @classmethod
    def load(cls, path: str | Path) -> XiPrior:
        """Read a file written by :meth:`save` (``allow_pickle=False``)."""
        with np.load(Path(path), allow_pickle=False) as z:
            precision = sparse.csr_array(
                (z["precision_data"], z["precision_indices"], z["precision_indptr"]),
                shape=(XI_DIM, XI_DIM),
            )
            return cls(
                mean=np.asarray(z["mean"], dtype=np.float64),
                precision=precision,
                members=np.asarray(z["members"], dtype=np.float64),
                meta=json.loads(str(z["meta"])),
            )


def default_drivers_dir() -> Path:
    """The package folder holding the shipped driver files."""
    return Path(str(resources.files("avrisk") / "data" / "drivers"))


def load_driver_net(path: str | Path | None = None) -> DriverNet:
    """The shipped (or a given) driver network, in eval mode.

    Parameters
    ----------
    path : str or Path, optional
        A ``driver_net.npz``; default the shipped one.

    Returns
    -------
    DriverNet
    """
    path = Path(path) if path is not None else default_drivers_dir() / DRIVER_NET_FILE
    return DriverNet.load(path).eval()


def load_xi_prior(path: str | Path | None = None) -> XiPrior:
    """The shipped (or a given) ``xi`` distribution.

    Parameters
    ----------
    path : str or Path, optional
        An ``xi_prior.npz``; default the shipped one.

    Returns
    -------
    XiPrior
    """
    path = Path(path) if path is not None else default_drivers_dir() / XI_PRIOR_FILE
    return XiPrior.load(path)
