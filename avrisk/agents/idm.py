"""IDM car following, MOBIL lane changes and a lane-keeping steering controller.

Vectorised over rollouts and vehicles at once: every vehicle of every rollout
is a driver; there is no Python loop over either. Parameters are per vehicle
(:class:`IDMParams`, shape (B, A)) so traffic is heterogeneous, and the same
model drives the environment (:class:`IDMDriver`, an actor of the simulator
for the vehicles it controls) or the ego under test (:class:`IDMPolicy`).

Longitudinal: the Intelligent Driver Model [1]_ with bumper-to-bumper gap ``s``
to the leader and approach rate ``dv = v - v_lead``,

    a_IDM = a (1 - (v / v0)^4 - (s* / s)^2),
    s* = s0 + max(0, v T + v dv / (2 sqrt(a b))).

A vehicle follows the nearest vehicle ahead in its lane and, while changing
lanes, also in its target lane (the smaller acceleration wins). A vehicle
*occupies* the lane containing its centre and, while changing, its target lane.

Lane change: MOBIL [2]_. Every ``LANE_CHANGE_DELAY`` seconds at most, a vehicle
settled in its lane considers the lane to each side and moves when

    a~_self - a_self + p (a~_new_follower - a_new_follower
                          + a~_old_follower - a_old_follower) > threshold,

where ``~`` marks accelerations after the change, and the change is safe: no
one (the new follower or the vehicle itself) would have to brake harder than
``LANE_CHANGE_MAX_BRAKING_IMPOSED``. With both sides acceptable the larger gain
wins (left on a tie).

Lateral: HighwayEnv's cascade [3]_ -- lateral position error to lateral speed
(time constant ``TAU_LATERAL``), to heading (clipped to
``MAX_HEADING_COMMAND``), to yaw rate (``TAU_HEADING``), to steering through
the inverse kinematic bicycle.

IDM is deterministic: it asks the simulator for no noise.

References
----------
.. [1] M. Treiber, A. Hennecke, D. Helbing, "Congested traffic states in
   empirical observations and microscopic simulations", Phys. Rev. E 62, 2000.
.. [2] A. Kesting, M. Treiber, D. Helbing, "General lane-changing model MOBIL
   for car-following models", Transp. Res. Rec. 1999, 2007.
.. [3] E. Leurent, "An environment for autonomous driving decision-making",
   HighwayEnv, 2018 (``IDMVehicle``, ``ControlledVehicle``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from avrisk.agents.neighbours import Neighbours, gather, lane_neighbours, own
from avrisk.agents.policy import ego_only, register_policy
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation
from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState
from avrisk.tensors.mathops import asin, atan, sqrt, wrap_angle
from avrisk.tensors.tensors import TensorDataclass

__all__ = [
    "ACC_MAX",
    "BRAKE_MAX",
    "IDMDriver",
    "IDMParams",
    "IDMPolicy",
    "IDMState",
    "idm_acceleration",
    "lateral_control",
]

# Longitudinal (HighwayEnv IDMVehicle where it has them).
ACC_MAX = 6.0  # [m/s2] strongest acceleration an IDM driver commands
BRAKE_MAX = 9.0  # [m/s2] strongest braking an IDM driver commands (emergency)
DELTA = 4.0  # [-] free-road exponent (the code squares twice)
GAP_FLOOR = 1e-2  # [m] bumper gaps below this count as this (overlap: full braking)
SPEED_FLOOR = 1e-2  # [m/s] speeds below this count as this in the controllers

# Lane change.
LANE_CHANGE_MAX_BRAKING_IMPOSED = 2.0  # [m/s2]
LANE_CHANGE_DELAY = 1.0  # [s] between lane-change decisions

# Lateral control.
TAU_LATERAL = 0.6  # [s]
TAU_HEADING = 0.2  # [s]
MAX_HEADING_COMMAND = math.pi / 4  # [rad] relative to the lane

# Defaults of IDMParams.full (HighwayEnv's, with Treiber's s0).
DEFAULT_PARAMS = {
    "desired_speed": 25.0,  # [m/s]
    "time_headway": 1.5,  # [s]
    "min_gap": 2.0,  # [m]
    "max_accel": 3.0,  # [m/s2] HighwayEnv COMFORT_ACC_MAX
    "comfort_decel": 5.0,  # [m/s2] -HighwayEnv COMFORT_ACC_MIN
    "politeness": 0.0,  # [-]
    "lane_change_threshold": 0.2,  # [m/s2] HighwayEnv LANE_CHANGE_MIN_ACC_GAIN
}


@dataclass(frozen=True)
class IDMParams(TensorDataclass):
    """Per-vehicle IDM+MOBIL parameters; every field a tensor of shape (B, A).

    Attributes
    ----------
    desired_speed : Tensor of shape (B, A)
        Free-road speed ``v0`` [m/s], > 0.
    time_headway : Tensor of shape (B, A)
        Desired time gap ``T`` [s], >= 0.
    min_gap : Tensor of shape (B, A)
        Jam distance ``s0`` (bumper to bumper) [m], >= 0.
    max_accel : Tensor of shape (B, A)
        IDM acceleration ``a`` [m/s^2], > 0.
    comfort_decel : Tensor of shape (B, A)
        Comfortable deceleration ``b`` [m/s^2], > 0.
    politeness : Tensor of shape (B, A)
        MOBIL politeness ``p`` [-], >= 0.
    lane_change_threshold : Tensor of shape (B, A)
        MOBIL incentive threshold [m/s^2].

    Examples
    --------
    >>> p = IDMParams.full((2, 3), desired_speed=30.0)
    >>> p.shape, p.desired_speed[0, 0].item(), p.time_headway[0, 0].item()
    (torch.Size([2, 3]), 30.0, 1.5)
    """

    desired_speed: Tensor  # [B, A] m/s
    time_headway: Tensor  # [B, A] s
    min_gap: Tensor  # [B, A] m
    max_accel: Tensor  # [B, A] m/s^2
    comfort_decel: Tensor  # [B, A] m/s^2
    politeness: Tensor  # [B, A] -
    lane_change_threshold: Tensor  # [B, A] m/s^2

    @classmethod
    def full(
        cls,
        shape: tuple[int, ...],
        *,
        dtype: torch.dtype = torch.float32,
        device: str | torch.device = "cpu",
        **values: float,
    ) -> IDMParams:
        """Parameters equal for every vehicle, defaults where not given.

        Parameters
        ----------
        shape : tuple of int
            ``(B, A)``.
        dtype : torch.dtype, default=torch.float32
        device : str or torch.device, default="cpu"
        **values : float
            Field values overriding ``DEFAULT_PARAMS`` (units as the fields).
        """
        unknown = set(values) - set(DEFAULT_PARAMS)
        if unknown:
            raise TypeError(f"unknown IDM parameters {sorted(unknown)}")
        merged = {**DEFAULT_PARAMS, **values}
        return cls(
            **{
                k: torch.full(shape, float(v), dtype=dtype, device=device)
                for k, v in merged.items()
            }
        )

    def validate(self) -> IDMParams:
        """Check shapes and ranges; return ``self``.

        Raises
        ------
        ValueError
            Naming the first field with the wrong shape or an out-of-range value.
        """
        self._check_same_shape()
        checks = {
            "desired_speed": lambda t: t > 0,
            "time_headway": lambda t: t >= 0,
            "min_gap": lambda t: t >= 0,
            "max_accel": lambda t: t > 0,
            "comfort_decel": lambda t: t > 0,
            "politeness": lambda t: t >= 0,
            "lane_change_threshold": torch.isfinite,
        }
        for name, ok in checks.items():
            t = getattr(self, name)
            if not t.is_floating_point():
                raise ValueError(f"IDMParams.{name} must be a floating tensor")
            if not bool((ok(t) & torch.isfinite(t)).all()):
                raise ValueError(
                    f"IDMParams.{name} out of range (min {t.min().item()}, "
                    f"max {t.max().item()}); see the IDMParams docstring"
                )
        return self


@dataclass(frozen=True)
class IDMState(TensorDataclass):
    """Memory of the IDM+MOBIL drivers.

    Attributes
    ----------
    target_lane : Tensor of int64, shape (B, A)
        Lane each vehicle steers to.
    since_change : Tensor of int64, shape (B, A)
        Steps since the last lane change began, capped at the decision delay
        (a vehicle may decide again once a full delay has passed).
    """

    target_lane: Tensor  # [B, A] int64
    since_change: Tensor  # [B, A] int64


def idm_acceleration(
    speed: Tensor,
    gap: Tensor,
    lead_speed: Tensor,
    desired_speed: Tensor,
    time_headway: Tensor,
    min_gap: Tensor,
    max_accel: Tensor,
    comfort_decel: Tensor,
) -> Tensor:
    """IDM acceleration (not clipped).

    Parameters
    ----------
    speed : Tensor of shape (...)
        Own speed [m/s] (negative counts as 0).
    gap : Tensor of shape (...)
        Bumper-to-bumper gap to the leader [m]; ``inf`` for a free road.
    lead_speed : Tensor of shape (...)
        Leader speed [m/s]; any finite value on a free road.
    desired_speed, time_headway, min_gap, max_accel, comfort_decel : Tensor
        IDM parameters (see :class:`IDMParams`), broadcastable to ``(...)``.

    Returns
    -------
    Tensor of shape (...)
        Acceleration [m/s^2].

    Examples
    --------
    >>> t = torch.tensor
    >>> free = idm_acceleration(t(10.0), t(math.inf), t(0.0), t(20.0), t(1.5),
    ...                         t(2.0), t(1.0), t(1.5))
    >>> round(free.item(), 6)  # 1 * (1 - (10 / 20)^4)
    0.9375
    """
    v = torch.clamp_min(speed, 0.0)
    r = v / desired_speed
    r2 = r * r
    free = max_accel * (1.0 - r2 * r2)
    dynamic = v * time_headway + v * (v - lead_speed) / (
        2.0 * sqrt(max_accel * comfort_decel)
    )
    s_star = min_gap + torch.clamp_min(dynamic, 0.0)
    q = s_star / torch.clamp_min(gap, GAP_FLOOR)
    return free - max_accel * (q * q)


def lateral_control(
    lateral_error: Tensor, heading: Tensor, speed: Tensor, rear_axle: Tensor
) -> Tensor:
    """Steering that brings a vehicle onto a straight lane centre line.

    Parameters
    ----------
    lateral_error : Tensor of shape (...)
        Position minus target centre line, lateral [m] (positive: left of it).
    heading : Tensor of shape (...)
        Heading relative to the lane [rad].
    speed : Tensor of shape (...)
        Speed [m/s].
    rear_axle : Tensor of shape (...)
        Distance from the centre to the rear axle ``l_r`` [m].

    Returns
    -------
    Tensor of shape (...)
        Front-wheel angle [rad] (the simulator clips it to its limit).
    """
    v = torch.clamp_min(speed, SPEED_FLOOR)
    lateral_speed = lateral_error * (-1.0 / TAU_LATERAL)
    heading_ref = torch.clamp(
        asin(lateral_speed / v), -MAX_HEADING_COMMAND, MAX_HEADING_COMMAND
    )
    yaw_rate = wrap_angle(heading_ref - heading) * (1.0 / TAU_HEADING)
    # Inverse bicycle: yaw rate = v sin(beta) / l_r, tan(steer) = 2 tan(beta).
    sin_beta = torch.clamp(rear_axle * yaw_rate / v, -1.0, 1.0)
    tan_beta = sin_beta / sqrt(1.0 - sin_beta * sin_beta)
    return atan(2.0 * tan_beta)


def _lane_accelerations(
    s: VehicleState, p: IDMParams, near: Neighbours
) -> tuple[Tensor, Tensor, Tensor]:
    """IDM accelerations in each queried lane, each (B, A, 4) [m/s^2].

    The vehicle's own behind that lane's leader; that lane's follower behind
    the vehicle; and the follower behind the leader, as if the vehicle were
    not there (0 without a follower).
    """
    lead_dx, lead, fol_dx, fol, has_lead, has_fol = near

    def idm(v: Tensor, gap: Tensor, v_lead: Tensor, who: Tensor | None) -> Tensor:
        def par(t: Tensor) -> Tensor:
            return own(t) if who is None else gather(t, who)

        return idm_acceleration(
            v,
            gap,
            v_lead,
            par(p.desired_speed),
            par(p.time_headway),
            par(p.min_gap),
            par(p.max_accel),
            par(p.comfort_decel),
        )

    v_a, len_a = own(s.speed), own(s.length)
    len_lead, len_fol = gather(s.length, lead), gather(s.length, fol)
    v_lead = torch.where(has_lead, gather(s.speed, lead), v_a)
    v_fol = gather(s.speed, fol)

    lead_gap = torch.where(has_lead, lead_dx - 0.5 * (len_a + len_lead), math.inf)
    # (B, A, 4): a behind the leader of each queried lane.
    acc_self = idm(v_a, lead_gap, v_lead, None)
    fol_gap_self = -fol_dx - 0.5 * (len_a + len_fol)
    fol_gap_lead = torch.where(
        has_lead, (lead_dx - fol_dx) - 0.5 * (len_lead + len_fol), math.inf
    )
    acc_fol_behind_self = torch.where(has_fol, idm(v_fol, fol_gap_self, v_a, fol), 0.0)
    acc_fol_behind_lead = torch.where(
        has_fol, idm(v_fol, fol_gap_lead, v_lead, fol), 0.0
    )
    return acc_self, acc_fol_behind_self, acc_fol_behind_lead


class IDMDriver:
    """IDM + MOBIL + lane keeping (an actor of the simulator).

    It computes every vehicle's action, shape (B, A); the simulator uses those
    of the vehicles it ``controlled``.

    Parameters
    ----------
    params : IDMParams
        Fields of shape (B, A), matching the simulated batch.
    road : Road
    wheelbase_fraction : float, default=0.6
        Wheelbase over length of the vehicles [-], as in the simulator's
        bicycle model (used by the steering controller).
    controlled : Tensor of bool, shape (A,), optional
        The vehicles this actor drives; default all. The others are driven by
        another actor: IDM+MOBIL sees them in the lane they are in, never
        changing lanes. Their ``params`` are how MOBIL predicts their
        reactions.
    """

    #: IDM and MOBIL find leaders and followers from the privileged state.
    reads_lidar = False
    #: Deterministic.
    noise = None

    def __init__(
        self,
        params: IDMParams,
        road: Road,
        *,
        wheelbase_fraction: float = 0.6,
        controlled: Tensor | None = None,
    ):
        self.params = params
        self.road = road
        self.wheelbase_fraction = wheelbase_fraction
        if controlled is None:
            device = params.desired_speed.device
            controlled = torch.ones(params.shape[-1], dtype=torch.bool, device=device)
        self.controlled = controlled

    def init(self, obs: Observation, params: None) -> IDMState:
        """Every vehicle keeps the lane it starts in, ready to decide.

        The parameters come with the constructor (``params`` must be None).
        """
        lane = self.road.lane_index(obs.state.y)
        delay = self._delay_steps(obs.dt)
        return IDMState(target_lane=lane, since_change=torch.full_like(lane, delay))

    @staticmethod
    def _delay_steps(dt: float) -> int:
        return max(1, round(LANE_CHANGE_DELAY / dt))

    def act(
        self, obs: Observation, state: IDMState, noise: None
    ) -> tuple[Action, IDMState]:
        """Accelerations and steering of all vehicles, shape (B, A), and new memory."""
        s, p, road = obs.state, self.params, self.road
        lane = self.road.lane_index(s.y)
        # Other actors' vehicles occupy only their lane (see __init__).
        target = torch.where(self.controlled, state.target_lane, lane)
        near = lane_neighbours(s, lane, target)
        acc_self, acc_fol_behind_self, acc_fol_behind_lead = _lane_accelerations(
            s, p, near
        )
        # MOBIL for the left (2) and right (3) lanes.
        acc_now = acc_self[..., 0]
        gain_self = acc_self[..., 2:] - acc_now.unsqueeze(-1)
        gain_new_fol = acc_fol_behind_self[..., 2:] - acc_fol_behind_lead[..., 2:]
        gain_old_fol = acc_fol_behind_lead[..., 0] - acc_fol_behind_self[..., 0]
        gain = gain_self + own(p.politeness) * (gain_new_fol + own(gain_old_fol))
        safe = (acc_fol_behind_self[..., 2:] >= -LANE_CHANGE_MAX_BRAKING_IMPOSED) & (
            acc_self[..., 2:] >= -LANE_CHANGE_MAX_BRAKING_IMPOSED
        )
        exists = torch.stack([lane + 1 < road.n_lanes, lane >= 1], dim=-1)
        delay = self._delay_steps(obs.dt)
        since = torch.clamp_max(state.since_change + 1, delay)
        ready = (target == lane) & (since >= delay)
        ok = exists & safe & (gain > own(p.lane_change_threshold)) & own(ready)
        go_left = ok[..., 0] & (~ok[..., 1] | (gain[..., 0] >= gain[..., 1]))
        go_right = ok[..., 1] & ~go_left
        changed = go_left | go_right
        target = torch.where(go_left, lane + 1, torch.where(go_right, lane - 1, target))
        since = torch.where(changed, 0, since)

        accel = torch.minimum(acc_now, acc_self[..., 1])
        accel = torch.clamp(accel, -BRAKE_MAX, ACC_MAX)
        accel = torch.maximum(accel, s.speed * (-1.0 / obs.dt))  # stop, never reverse

        target_y = (target.to(s.y.dtype) + 0.5) * road.lane_width
        rear_axle = (0.5 * self.wheelbase_fraction) * s.length
        steer = lateral_control(s.y - target_y, s.heading, s.speed, rear_axle)
        return Action(accel=accel, steer=steer), IDMState(
            target_lane=target, since_change=since
        )


class IDMPolicy:
    """IDM + MOBIL as the ego policy: an actor that controls vehicle 0.

    It drives the ego exactly as an :class:`IDMDriver` of every vehicle would,
    with privileged knowledge of everyone's parameters (MOBIL predicts every
    vehicle, the ego's own lane changes included, as IDM+MOBIL).

    Parameters
    ----------
    params : IDMParams
        Fields of shape (B, A); row ``[:, 0]`` is the ego's.
    road : Road
    wheelbase_fraction : float, default=0.6
    """

    reads_lidar = False
    noise = None

    def __init__(
        self, params: IDMParams, road: Road, *, wheelbase_fraction: float = 0.6
    ):
        self.driver = IDMDriver(params, road, wheelbase_fraction=wheelbase_fraction)
        self.controlled = ego_only(params.shape[-1], device=params.desired_speed.device)

    def init(self, obs: Observation, params: None) -> IDMState:
        """See :meth:`IDMDriver.init`."""
        return self.driver.init(obs, params)

    def act(
        self, obs: Observation, state: IDMState, noise: None
    ) -> tuple[Action, IDMState]:
        """Every vehicle's IDM+MOBIL action, (B, A); the ego's column counts."""
        return self.driver.act(obs, state, noise)


def _idm_policy_factory(**kwargs: Any) -> IDMPolicy:
    return IDMPolicy(**kwargs)


register_policy("idm_mobil", _idm_policy_factory)
