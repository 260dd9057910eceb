"""Learned environment drivers (paper, appendix B): network, ``xi``, ensemble prior.

* :mod:`~avrisk.agents.drivers.features` -- the 51 input features, defined once;
* :mod:`~avrisk.agents.drivers.xi` -- the 404-number last layer ``xi``;
* :mod:`~avrisk.agents.drivers.network` -- :class:`DriverNet`, a per-rollout
  ``xi`` in one batched pass;
* :mod:`~avrisk.agents.drivers.driver` -- :class:`LearnedDriver` (environment)
  and :class:`LearnedEgoPolicy` (registered as ``"lidar_imitation"``);
* :mod:`~avrisk.agents.drivers.lane_change` -- :class:`LaneChangingDriver`, a
  lane-change intention (hazard, gap acceptance) on top of a learned driver;
* :mod:`~avrisk.agents.drivers.store` -- the shipped weights and
  ``xi ~ N(mu0, Sigma0)``.

Training lives in :mod:`avrisk.learning`.
"""

from avrisk.agents.drivers.driver import LearnedDriver, LearnedEgoPolicy
from avrisk.agents.drivers.features import (
    FEATURE_NAMES,
    N_FEATURES,
    assemble_features,
    features_from_observation,
)
from avrisk.agents.drivers.lane_change import LaneChangeParams, LaneChangingDriver
from avrisk.agents.drivers.network import ActionDistribution, DriverNet
from avrisk.agents.drivers.store import XiPrior, load_driver_net, load_xi_prior
from avrisk.agents.drivers.xi import XI_DIM, pack_xi, unpack_xi

__all__ = [
    "FEATURE_NAMES",
    "N_FEATURES",
    "XI_DIM",
    "ActionDistribution",
    "DriverNet",
    "LaneChangeParams",
    "LaneChangingDriver",
    "LearnedDriver",
    "LearnedEgoPolicy",
    "XiPrior",
    "assemble_features",
    "features_from_observation",
    "load_driver_net",
    "load_xi_prior",
    "pack_xi",
    "unpack_xi",
]
