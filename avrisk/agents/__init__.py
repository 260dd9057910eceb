"""Drivers and ego policies: observations in, actions out.

Importing the package registers every ego policy by name (``"constant"``,
``"idm_mobil"``, ``"lidar_imitation"``; :func:`get_policy`).
"""

from avrisk.agents.drivers import LearnedDriver, LearnedEgoPolicy
from avrisk.agents.idm import IDMDriver, IDMParams, IDMPolicy, IDMState
from avrisk.agents.mixed import MixedDriver
from avrisk.agents.policy import (
    Action,
    ConstantPolicy,
    DriverModel,
    Policy,
    get_policy,
    register_policy,
)

__all__ = [
    "Action",
    "ConstantPolicy",
    "DriverModel",
    "IDMDriver",
    "IDMParams",
    "IDMPolicy",
    "IDMState",
    "LearnedDriver",
    "LearnedEgoPolicy",
    "MixedDriver",
    "Policy",
    "get_policy",
    "register_policy",
]
