"""Kinematic bicycle model, referenced at the centre of the rectangle.

Model (Rajamani 2012, section 2.2; HighwayEnv's ``Vehicle.step``): the centre
of mass sits midway between the axles, ``l_f = l_r = wheelbase / 2`` with
``wheelbase = wheelbase_fraction * length``. With front-wheel steering angle
``delta`` the centre moves at slip angle ``beta`` to the heading,

    tan(beta) = l_r / (l_f + l_r) * tan(delta) = tan(delta) / 2,
    d(heading)/dt = speed * sin(beta) / l_r,
    d(position)/dt = speed * (cos(heading + beta), sin(heading + beta)),
    d(speed)/dt = acceleration.

Integration over one step ``dt`` holds acceleration and steering constant and
is exact for the two motions that matter: straight-line constant acceleration
(position advances by the mean speed ``(v + v') / 2`` times ``dt``) and
constant-speed turning (the centre moves along the chord of its circle,
``v dt sinc(dpsi / 2)`` in direction ``heading + beta + dpsi / 2``). The mean
speed also sets the turn, so combined motion is second-order accurate.

Physical limits (all in :class:`~avrisk.sim.config.SimConfig`): commanded
acceleration is clipped to ``[accel_min, accel_max]``, steering to
``[-max_steer, max_steer]``, speed to ``[min_speed, max_speed]`` (a negative
speed is driving backwards).

References
----------
.. [1] R. Rajamani, *Vehicle Dynamics and Control*, 2nd ed., Springer, 2012.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from avrisk.sim.state import VehicleState
from avrisk.tensors.mathops import sinc, sincos, sqrt

__all__ = ["BicycleLimits", "bicycle_step"]


@dataclass(frozen=True)
class BicycleLimits:
    """Physical limits and geometry of the kinematic bicycle.

    Parameters
    ----------
    accel_min : float, default=-9.0
        Strongest braking [m/s^2] (about 0.9 g, dry asphalt).
    accel_max : float, default=6.0
        Strongest acceleration [m/s^2] (HighwayEnv ``ACC_MAX``).
    max_steer : float, default=0.6
        Largest front-wheel angle [rad] (about 34 degrees).
    min_speed : float, default=-10.0
        Fastest reverse speed [m/s].
    max_speed : float, default=45.0
        Top speed [m/s].
    wheelbase_fraction : float, default=0.6
        Wheelbase as a fraction of the vehicle length [-] (a 4.8 m car has a
        2.9 m wheelbase).
    """

    accel_min: float = -9.0  # [m/s^2]
    accel_max: float = 6.0  # [m/s^2]
    max_steer: float = 0.6  # [rad]
    min_speed: float = -10.0  # [m/s]
    max_speed: float = 45.0  # [m/s]
    wheelbase_fraction: float = 0.6  # [-]

    def __post_init__(self) -> None:
        if not self.accel_min < 0 < self.accel_max:
            raise ValueError(
                f"need accel_min < 0 < accel_max [m/s^2]; got {self.accel_min}, "
                f"{self.accel_max}"
            )
        if not 0 < self.max_steer < 1.5:
            raise ValueError(
                f"max_steer must be in (0, 1.5) [rad]; got {self.max_steer}"
            )
        if not self.min_speed <= 0 < self.max_speed:
            raise ValueError(
                f"need min_speed <= 0 < max_speed [m/s]; got {self.min_speed}, "
                f"{self.max_speed}"
            )
        if not 0 < self.wheelbase_fraction <= 1:
            raise ValueError(
                f"wheelbase_fraction must be in (0, 1]; got {self.wheelbase_fraction}"
            )


def bicycle_step(
    state: VehicleState,
    accel: Tensor,
    steer: Tensor,
    dt: float,
    limits: BicycleLimits = BicycleLimits(),
    heading_cos_sin: tuple[Tensor, Tensor] | None = None,
) -> VehicleState:
    """Advance every vehicle by one time step.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (B, A).
    accel : Tensor of shape (B, A)
        Commanded acceleration along the heading [m/s^2].
    steer : Tensor of shape (B, A)
        Commanded front-wheel angle [rad], positive turns left.
    dt : float
        Time step [s].
    limits : BicycleLimits
        Physical limits and wheelbase.
    heading_cos_sin : tuple of Tensor of shape (B, A), optional
        ``state.cos_sin`` when the caller already has it (the simulator
        does); computed here otherwise.

    Returns
    -------
    VehicleState
        The state ``dt`` later, fields of shape (B, A).
    """
    accel = torch.clamp(accel, limits.accel_min, limits.accel_max)
    steer = torch.clamp(steer, -limits.max_steer, limits.max_steer)
    speed_new = torch.clamp(
        state.speed + accel * dt, limits.min_speed, limits.max_speed
    )
    speed_mean = 0.5 * (state.speed + speed_new)

    sin_d, cos_d = sincos(steer)
    tan_beta = 0.5 * sin_d / cos_d  # |steer| < pi/2: cos > 0
    cos_beta = 1.0 / sqrt(1.0 + tan_beta * tan_beta)
    sin_beta = tan_beta * cos_beta
    l_r = (0.5 * limits.wheelbase_fraction) * state.length
    dpsi = speed_mean * sin_beta / l_r * dt

    half = 0.5 * dpsi
    cos_h, sin_h = state.cos_sin if heading_cos_sin is None else heading_cos_sin
    sin_m, cos_m = sincos(half)
    # Direction of travel heading + beta + dpsi/2, by rotation composition.
    cos_hb = cos_h * cos_beta - sin_h * sin_beta
    sin_hb = sin_h * cos_beta + cos_h * sin_beta
    cos_t = cos_hb * cos_m - sin_hb * sin_m
    sin_t = sin_hb * cos_m + cos_hb * sin_m
    chord = speed_mean * dt * sinc(half, sin_m)
    return VehicleState(
        x=state.x + chord * cos_t,
        y=state.y + chord * sin_t,
        heading=state.heading + dpsi,
        speed=speed_new,
        length=state.length,
        width=state.width,
    )
