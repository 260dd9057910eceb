"""Demonstrations for behaviour cloning: (features, action) pairs with weights.

:class:`Demonstrations` holds the pairs of every source, tagged by
:data:`SOURCE_NAMES`; the builders live with their data:

* **NGSIM I-80 car-following pairs** and **I-80 pairs with lateral positions**
  (:mod:`avrisk.learning.imitation.ngsim_demonstrations`): human *longitudinal*
  behaviour behind a leader, and human lane keeping where the data have
  lateral positions;
* **Our own simulator with IDM drivers**
  (:mod:`avrisk.learning.imitation.simulated_demonstrations`): multi-lane traffic,
  neighbours in other lanes and vehicles cutting in, which the NGSIM pairs
  lack. These demonstrations are *not human*: their acceleration targets carry
  a lower weight than the human ones. Lane changes are not demonstrated.

One code path for features
--------------------------
Every source observes its scenes with :func:`observing_simulator`, and its
features come from the simulator's own observation
(:meth:`avrisk.sim.Simulator.observe`) through
:func:`avrisk.agents.drivers.features.features_from_observation`: exactly the
code that produces the network's inputs in closed loop. The only difference is
what is in the scene: the NGSIM files have no other neighbours, so the lidar's
side beams see only the road edges.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from avrisk.agents.drivers.features import N_BEAMS, N_FEATURES
from avrisk.safety import MinTTC
from avrisk.sim import Road, SimConfig, Simulator

__all__ = [
    "LIDAR_RANGE",
    "SOURCE_I80",
    "SOURCE_I80_LATERAL",
    "SOURCE_IDM",
    "SOURCE_NAMES",
    "Demonstrations",
    "observing_simulator",
]

SOURCE_I80, SOURCE_I80_LATERAL, SOURCE_IDM = 0, 1, 2
SOURCE_NAMES = {
    SOURCE_I80: "ngsim_i80_pairs",
    SOURCE_I80_LATERAL: "ngsim_i80_lateral",
    SOURCE_IDM: "sim_idm_mobil",
}
#: Lidar range of the driver features [m] (the scenario default).
LIDAR_RANGE = 50.0


@dataclass(frozen=True)
class Demonstrations:
    """Behaviour-cloning samples; every field has leading length ``N``.

    Attributes
    ----------
    features : ndarray of float32, shape (N, N_FEATURES)
        Driver-network inputs (:mod:`avrisk.agents.drivers.features`).
    accel : ndarray of float32, shape (N,)
        Target acceleration [m/s^2].
    steer : ndarray of float32, shape (N,)
        Target front-wheel angle [rad].
    accel_weight, steer_weight : ndarray of float32, shape (N,)
        Loss weight of each target [-]; 0 where the target is unknown.
    episode : ndarray of int64, shape (N,)
        Trajectory id, unique across sources: the unit of bootstrap resampling.
    source : ndarray of int8, shape (N,)
        :data:`SOURCE_NAMES` key.
    """

    features: NDArray[np.float32]
    accel: NDArray[np.float32]
    steer: NDArray[np.float32]
    accel_weight: NDArray[np.float32]
    steer_weight: NDArray[np.float32]
    episode: NDArray[np.int64]
    source: NDArray[np.int8]

    def __post_init__(self) -> None:
        n = len(self.accel)
        if self.features.shape != (n, N_FEATURES):
            raise ValueError(
                f"features must have shape ({n}, {N_FEATURES}); got "
                f"{self.features.shape}"
            )
        for f in dataclasses.fields(self):
            if len(getattr(self, f.name)) != n:
                raise ValueError(f"Demonstrations.{f.name} must have length {n}")

    def __len__(self) -> int:
        return len(self.accel)

    def take(self, index: Any) -> Demonstrations:
        """Rows ``index`` (mask, slice or integer array)."""
        return dataclasses.replace(
            self,
            **{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)},
        )

    @classmethod
    def concat(cls, parts: Sequence[Demonstrations]) -> Demonstrations:
        """Stack several sets row-wise."""
        return cls(
            **{
                f.name: np.concatenate([getattr(p, f.name) for p in parts])
                for f in dataclasses.fields(cls)
            }
        )

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (no pickle)."""
        np.savez(
            Path(path),
            **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)},
        )

    @classmethod
    def load(cls, path: str | Path) -> Demonstrations:
        """Read a file written by :meth:`save`."""
        with np.load(Path(path), allow_pickle=False) as z:
            return cls(**{f.name: z[f.name] for f in dataclasses.fields(cls)})

    def summary(self) -> dict[str, dict[str, float]]:
        """Rows, episodes and weighted target counts per source."""
        out = {}
        for code, name in SOURCE_NAMES.items():
            m = self.source == code
            if m.any():
                out[name] = {
                    "rows": int(m.sum()),
                    "episodes": int(np.unique(self.episode[m]).size),
                    "accel_targets": float(self.accel_weight[m].sum()),
                    "steer_targets": float(self.steer_weight[m].sum()),
                }
        return out


def observing_simulator(road: Road, horizon: float = SimConfig.horizon) -> Simulator:
    """A simulator whose observations carry the driver network's lidar.

    ``N_BEAMS`` beams of ``LIDAR_RANGE`` m, as the features expect; one TTC ray,
    since demonstrations never read the safety measure. ``horizon`` in s.
    """
    config = SimConfig(horizon=horizon, n_lidar_beams=N_BEAMS, lidar_range=LIDAR_RANGE)
    return Simulator(road, config, measure=MinTTC(n_rays=1))
