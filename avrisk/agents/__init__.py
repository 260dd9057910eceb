"""Drivers and ego policies: observations in, actions out."""

from avrisk.agents.idm import IDMDriver, IDMParams, IDMPolicy, IDMState
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
    "Policy",
    "get_policy",
    "register_policy",
]
