"""Drivers and ego policies: actors of the simulator (observations in, actions out).

Each implements :class:`avrisk.sim.interfaces.Actor` for the vehicles it
controls. Importing the package registers every ego policy by name
(``"constant"``, ``"idm_mobil"``, ``"lidar_imitation"``, ``"vision_pilotnet"``:
PilotNet on the ego camera, :mod:`avrisk.agents.vision`; ``"external"``: an AV
in another process over ZeroMQ, :mod:`avrisk.agents.external`;
:func:`get_policy`);
other driver models than IDM+MOBIL and the learned one come by name or import
path through :func:`get_driver_model`.
"""

from avrisk.agents.driver_models import get_driver_model, register_driver_model
from avrisk.agents.drivers import LearnedDriver, LearnedEgoPolicy
from avrisk.agents.external import EXTERNAL
from avrisk.agents.idm import IDMDriver, IDMParams, IDMPolicy, IDMState
from avrisk.agents.policy import (
    ConstantPolicy,
    EgoActor,
    EgoPolicy,
    as_ego_actor,
    ego_only,
    get_policy,
    register_policy,
)
from avrisk.agents.vision import PilotNet, PilotNetEgo

__all__ = [
    "EXTERNAL",
    "ConstantPolicy",
    "EgoActor",
    "EgoPolicy",
    "IDMDriver",
    "IDMParams",
    "IDMPolicy",
    "IDMState",
    "LearnedDriver",
    "LearnedEgoPolicy",
    "PilotNet",
    "PilotNetEgo",
    "as_ego_actor",
    "ego_only",
    "get_driver_model",
    "get_policy",
    "register_driver_model",
    "register_policy",
]
