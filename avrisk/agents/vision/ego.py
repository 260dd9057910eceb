"""The paper's vision ego: PilotNet steers from the camera, the lidar net throttles.

Paper, appendix C: "this highway autopilot model uses rendered images to
produce steering commands. Lidar inputs are used to generate throttle
commands using the same network as the non-vision policy." So
:class:`PilotNetEgo` drives vehicle 0 with

* steering: :meth:`PilotNet.steer` on the ego camera's RGB image
  (``obs.camera.rgb``, which the simulator renders because the ego says
  ``reads_camera = True``);
* acceleration: the lidar ego's (:class:`~avrisk.agents.drivers.LearnedEgoPolicy`,
  its mean action on the ego's lidar and lane features).

It is registered as the ego policy ``vision_pilotnet``, with the shipped
weights (:func:`~avrisk.agents.vision.store.load_pilotnet`).
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor

from avrisk.agents.drivers.driver import LearnedEgoPolicy, LearnedState
from avrisk.agents.drivers.network import DriverNet
from avrisk.agents.policy import register_policy
from avrisk.agents.vision.pilotnet import PilotNet
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = ["PilotNetEgo"]


class PilotNetEgo:
    """PilotNet steering with the lidar ego's throttle (an actor of vehicle 0).

    Parameters
    ----------
    net : PilotNet
        On the simulator's device.
    throttle : LearnedEgoPolicy
        The lidar ego whose acceleration it takes (its steering is not used).
    weights_files : dict of str to Path, optional
        The files ``net`` was loaded from (a provenance stamp hashes them).

    Attributes
    ----------
    controlled : Tensor of bool, shape (A,)
        Vehicle 0 only.
    weights_files : dict of str to Path
    """

    #: The throttle reads the ego's lidar; the steering reads the camera.
    reads_lidar = True
    reads_camera = True
    noise = None

    def __init__(
        self,
        net: PilotNet,
        throttle: LearnedEgoPolicy,
        weights_files: dict[str, Path] | None = None,
    ) -> None:
        if throttle.noise is not None:
            raise ValueError("the throttle ego must act with its mean action")
        self.net = net.eval()
        self.weights_files = dict(weights_files or {})
        self.throttle = throttle
        self.controlled = throttle.controlled

    def init(self, obs: Observation, params: Tensor | None) -> LearnedState:
        """The throttle's state (the steering network keeps none)."""
        return self.throttle.init(obs, params)

    def act(
        self, obs: Observation, state: LearnedState, noise: None
    ) -> tuple[Action, LearnedState]:
        """The ego's action in every column, fields of shape (B, A).

        Raises
        ------
        ValueError
            If the observation carries no camera image.
        """
        if obs.camera is None:
            raise ValueError(
                "PilotNetEgo needs obs.camera; run it in a simulator with a camera"
            )
        action, state = self.throttle.act(obs, state, None)
        steer = self.net.steer(obs.camera.rgb.to(self.net.steer_mean.dtype))
        steer = steer.to(obs.state.x.dtype).unsqueeze(-1).expand(obs.state.shape)
        return Action(accel=action.accel, steer=steer), state


def _vision_ego_factory(
    *,
    n_vehicles: int,
    net: DriverNet | None = None,
    device: str | torch.device = "cpu",
) -> PilotNetEgo:
    """The shipped PilotNet with the shipped lidar ego's throttle."""
    from avrisk.agents.drivers.store import load_driver_net
    from avrisk.agents.vision.store import (
        PILOTNET_FILE,
        default_vision_dir,
        load_pilotnet,
    )

    driver_net = load_driver_net().to(device) if net is None else net
    path = default_vision_dir() / PILOTNET_FILE
    return PilotNetEgo(
        load_pilotnet(path).to(device),
        LearnedEgoPolicy(driver_net, n_vehicles),
        {PILOTNET_FILE: path},
    )


register_policy("vision_pilotnet", _vision_ego_factory)
