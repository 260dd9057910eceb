"""What the AV under test observes and commands over the protocol.

The observation is the ego's (vehicle 0's) part of the simulator's
:class:`~avrisk.sim.observation.Observation`, as named arrays with the batch
first: its own state, its lane features, its flags and its lidar. Other
vehicles' states are not sent: a real AV knows them only through its sensors.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from avrisk.sim.observation import Observation

__all__ = ["ACTION_SPACE", "OBSERVATION_UNITS", "hello_message", "observation_arrays"]

#: Every observed field and its unit; each is an array of shape (B,), but the
#: lidar's (B, R); lane is int64, the flags uint8 (0/1), the rest the
#: simulator's float type. (Camera images are reserved for a later version.)
OBSERVATION_UNITS = {
    "x": "m",
    "y": "m",
    "heading": "rad",
    "speed": "m/s",
    "length": "m",
    "width": "m",
    "lane": "-",
    "lateral_offset": "m",
    "heading_offset": "rad",
    "left_marking": "m",
    "right_marking": "m",
    "left_edge": "m",
    "right_edge": "m",
    "curvature": "1/m",
    "collided": "-",
    "offroad": "-",
    "reversing": "-",
    "lidar_range": "m",
    "lidar_range_rate": "m/s",
}
#: The action the AV returns per rollout: arrays of shape (B,).
ACTION_SPACE = {"accel": {"unit": "m/s^2"}, "steer": {"unit": "rad"}}

_STATE = ("x", "y", "heading", "speed", "length", "width")
_LANE = (
    "lane",
    "lateral_offset",
    "heading_offset",
    "left_marking",
    "right_marking",
    "left_edge",
    "right_edge",
    "curvature",
)
_FLAGS = ("collided", "offroad", "reversing")


def observation_arrays(obs: Observation) -> dict[str, np.ndarray]:
    """The ego's observation as named numpy arrays, batch first.

    Returns
    -------
    dict of str to ndarray
        The fields of :data:`OBSERVATION_UNITS`, each of shape (B,) but
        ``lidar_range`` and ``lidar_range_rate`` (B, R), present only when the
        simulator has a lidar.
    """

    def ego(t: Any) -> np.ndarray:
        return t[:, 0].detach().cpu().numpy()

    out = {name: ego(getattr(obs.state, name)) for name in _STATE}
    out.update({name: ego(getattr(obs.lane, name)) for name in _LANE})
    out.update({name: ego(getattr(obs, name)).astype(np.uint8) for name in _FLAGS})
    if obs.lidar is not None:
        out["lidar_range"] = ego(obs.lidar.range)
        out["lidar_range_rate"] = ego(obs.lidar.range_rate)
    return out


def hello_message(arrays: dict[str, np.ndarray], dt: float) -> dict[str, Any]:
    """The handshake request: protocol version, observation and action spaces.

    Parameters
    ----------
    arrays : dict of str to ndarray
        An observation (:func:`observation_arrays`), for the fields' dtypes and
        per-rollout shapes.
    dt : float
        Time step [s].
    """
    # Deferred: the protocol needs msgpack (the `external` extra); the
    # observation's fields above do not (the Gymnasium environment uses them).
    from avrisk.agents.external.protocol import PROTOCOL_VERSION, pack_array

    observation = {
        name: {
            "dtype": pack_array(a[:0])["dtype"],
            "shape": list(a.shape[1:]),
            "unit": OBSERVATION_UNITS[name],
        }
        for name, a in arrays.items()
    }
    lidar = arrays.get("lidar_range")
    n_beams = 0 if lidar is None else lidar.shape[1]
    return {
        "type": "hello",
        "protocol": PROTOCOL_VERSION,
        "dt": dt,
        "observation": observation,
        # Beam k points 2 pi k / R [rad] counter-clockwise from the heading.
        "lidar_angles": [2.0 * math.pi * k / n_beams for k in range(n_beams)],
        "action": ACTION_SPACE,
    }
