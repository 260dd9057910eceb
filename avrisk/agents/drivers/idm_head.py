"""A car-following head: the network sets the gap it keeps, the IDM the acceleration.

The driver network's free head (:mod:`avrisk.agents.drivers.network`) outputs
the mean acceleration itself. Trained on one period's traffic, it learns
closing behaviour that does not carry over to another: trained on flowing
traffic, it runs into stopping queues it never saw; trained on congested
traffic, it closes timidly in flowing traffic (BENCHMARKS.md, "Drivers on a
period they never saw"). This head puts the car-following law in the model
and leaves the network what varies between drivers and situations: its
first output ``r`` scales the gap the driver wants, and the Intelligent
Driver Model (:func:`~avrisk.agents.idm.idm_acceleration`) turns that gap
into the mean acceleration,

    k   = exp(R tanh(r / R)),  R = MAX_LOG_GAP_FACTOR               [-]
    a_I = IDM(v, g, v_lead; v0, k T, k s0, a, b)                    [m/s^2]
    a_m = a_min + softplus(a_I - a_min),  a_min = ACCEL_FLOOR       [m/s^2]

with ``v`` the driver's speed, ``g = range_0 - length / 2`` the bumper gap
along its front lidar beam and ``v_lead = v + range_rate_0`` the speed of
what that beam hits (a beam that hits nothing reads the lidar's range: a
gap that long barely brakes). The five IDM parameters are shared by every
driver and fitted with the network (as log factors on
:data:`INITIAL_PARAMS`, so weight decay pulls them to those values). The
IDM's interaction term grows without bound as the gap closes, whatever the
network says (``k >= exp(-R)``), so the mean acceleration always brakes
before a vehicle ahead, down to the simulator's floor ``a_min``, which it
approaches smoothly: the simulator clips every acceleration there anyway,
and a demonstration whose front beam meets what the driver did not brake
for (a vehicle in the next lane, half in front, while changing lanes) then
costs the fit a bounded error with a vanishing gradient, instead of one
that grows as the square of the IDM's demand and teaches every driver to
tailgate. The action noise around the mean is the network's, as with the
free head. ``xi`` (the last layer) still perturbs ``r``, so a
rare-event search over ``xi`` looks for drivers who keep short gaps.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from avrisk.agents.drivers.features import FEATURE_INDEX
from avrisk.agents.idm import idm_acceleration
from avrisk.sim.config import SimConfig

__all__ = [
    "ACCEL_FLOOR",
    "HEADS",
    "INITIAL_PARAMS",
    "MAX_LOG_GAP_FACTOR",
    "IDMHead",
    "check_head",
]

#: The heads a driver network may have: ``"free"`` outputs the mean
#: acceleration; ``"idm"`` the factor on the IDM's desired gap (this module).
HEADS = ("free", "idm")

#: ``(v0 [m/s], T [s], s0 [m], a [m/s^2], b [m/s^2])`` before training: the
#: desired speed, time headway, jam gap, maximum acceleration and comfortable
#: deceleration of :class:`~avrisk.agents.idm.IDMParams`'s usual car, with a
#: desired speed of the I-80 traffic's order.
INITIAL_PARAMS = (20.0, 1.2, 2.0, 1.0, 1.5)

#: Bound ``R`` on the network's log factor of the desired gap: the gap may be
#: scaled by ``exp(-R)`` to ``exp(R)`` (about 0.05 to 20).
MAX_LOG_GAP_FACTOR = 3.0

#: The mean acceleration's smooth floor ``a_min`` [m/s^2]: the simulator's
#: default clip (:class:`~avrisk.sim.config.SimConfig`'s ``accel_min``).
ACCEL_FLOOR = SimConfig.accel_min

_SPEED = FEATURE_INDEX["speed"]
_LENGTH = FEATURE_INDEX["length"]
_RANGE = FEATURE_INDEX["range_0"]
_RATE = FEATURE_INDEX["range_rate_0"]


class IDMHead(nn.Module):
    """The IDM's five shared parameters and the mean acceleration they give.

    Attributes
    ----------
    log_factors : torch.nn.Parameter of shape (5,)
        ``log(param / INITIAL_PARAMS)``, in :data:`INITIAL_PARAMS`'s order.
    initial : Tensor of shape (5,)
        :data:`INITIAL_PARAMS` (a buffer, not saved: it moves with the module
        and is not built again at every step).
    """

    def __init__(self) -> None:
        super().__init__()
        self.log_factors = nn.Parameter(torch.zeros(len(INITIAL_PARAMS)))
        self.register_buffer("initial", torch.tensor(INITIAL_PARAMS), persistent=False)

    def params(self) -> Tensor:
        """``(v0, T, s0, a, b)`` as fitted, shape (5,), in their units."""
        return self.initial * torch.exp(self.log_factors)

    def mean_accel(self, raw: Tensor, features: Tensor) -> Tensor:
        """The mean acceleration [m/s^2] of every vehicle.

        Parameters
        ----------
        raw : Tensor of shape (...)
            The network's first output ``r``: the log factor on the desired
            gap, before its soft bound.
        features : Tensor of shape (..., N_FEATURES)
            The vehicles' unscaled features
            (:mod:`avrisk.agents.drivers.features`), broadcastable against
            ``raw``'s shape.

        Returns
        -------
        Tensor of shape (...)
            ``a_min + softplus(IDM(v, g, v_lead; v0, k T, k s0, a, b) - a_min)``.
        """
        v0, headway, jam_gap, max_accel, comfort = self.params().to(raw.dtype)
        factor = torch.exp(MAX_LOG_GAP_FACTOR * torch.tanh(raw / MAX_LOG_GAP_FACTOR))
        features = features.to(raw.dtype)
        speed = features[..., _SPEED]
        gap = features[..., _RANGE] - 0.5 * features[..., _LENGTH]
        demand = idm_acceleration(
            speed,
            gap,
            speed + features[..., _RATE],
            v0,
            headway * factor,
            jam_gap * factor,
            max_accel,
            comfort,
        )
        return ACCEL_FLOOR + F.softplus(demand - ACCEL_FLOOR)


def check_head(head: str) -> str:
    """``head`` if it is one of :data:`HEADS`; a ValueError naming them otherwise."""
    if head not in HEADS:
        raise ValueError(f"head must be one of {', '.join(HEADS)}; got {head!r}")
    return head
