"""Which learned drivers a scenario's traffic uses, the ego under test left alone.

By default a scenario's learned traffic drivers and the ``lidar_imitation``
ego load the same shipped network (``avrisk/data/drivers``), and ``P0``'s
``xi`` block is the shipped prior. To measure how much ``p`` depends on the
driver model (issue 44), the traffic must be swappable without swapping the
system under test: :class:`TrafficDrivers` names the traffic's files (a
folder ``avrisk train-drivers`` wrote) and its emergency brake;
:class:`~avrisk.assembly.builder.ScenarioSimulator` drives the traffic with
them while the ego keeps the shipped weights, and ``P0``'s ``xi`` block
becomes their prior (:meth:`TrafficDrivers.prior`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.drivers.store import (
    DRIVER_NET_FILE,
    XI_PRIOR_FILE,
    XiPrior,
    load_driver_net,
    load_xi_prior,
)

__all__ = ["OWN_GUARD", "TrafficDrivers"]

#: ``TrafficDrivers.guard``: the brake the traffic's weights carry.
OWN_GUARD = "drivers"


@dataclass(frozen=True)
class TrafficDrivers:
    """The learned traffic drivers: their files and their emergency brake.

    Parameters
    ----------
    folder : Path
        Holds ``driver_net.npz`` and ``xi_prior.npz`` (as ``avrisk
        train-drivers`` writes them).
    guard : BrakeGuard, None or "drivers", default="drivers"
        The traffic's emergency brake: :data:`OWN_GUARD` the one the weights
        carry, None none (the network alone), or another.
    """

    folder: Path
    guard: BrakeGuard | Literal["drivers"] | None = OWN_GUARD

    def __post_init__(self) -> None:
        known = self.guard is None or isinstance(self.guard, BrakeGuard)
        if not known and self.guard != OWN_GUARD:
            raise ValueError(
                f"guard must be a BrakeGuard, None or {OWN_GUARD!r}; got {self.guard!r}"
            )

    def files(self) -> dict[str, Path]:
        """The network's and the prior's paths, by file name."""
        return {name: self.folder / name for name in (DRIVER_NET_FILE, XI_PRIOR_FILE)}

    def net(self) -> DriverNet:
        """The traffic's network (eval mode), carrying the brake it drives with."""
        net = load_driver_net(self.folder / DRIVER_NET_FILE)
        if self.guard != OWN_GUARD:
            net.guard = self.guard
        return net

    def prior(self) -> XiPrior:
        """The traffic's ``xi ~ N(mu0, Sigma0)``."""
        return load_xi_prior(self.folder / XI_PRIOR_FILE)

    def describe(self) -> dict[str, Any]:
        """What defines the traffic, JSON-ready: folder and brake."""
        guard = self.guard
        return {
            "folder": str(self.folder),
            "guard": guard if guard in (None, OWN_GUARD) else guard.to_dict(),
        }
