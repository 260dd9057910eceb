"""Learned drivers in the simulator: the environment actor and the lidar ego.

:class:`LearnedDriver` is an actor of the simulator
(:class:`avrisk.sim.interfaces.Actor`): every vehicle of rollout ``b`` it
controls is driven by the network with last layer ``xi[b]``, its per-rollout
parameter block (one draw of ``xi ~ N(mu0, Sigma0)`` per rollout, as in the
paper; columns of ``X``). Actions are sampled from the network's Gaussians with
noise the simulator draws for it (:class:`~avrisk.sim.interfaces.NoiseRequest`,
counter-based: a pure function of the rollout's seed, the step, the vehicle
and the action), so a rollout gets the same noise alone or in any batch.
:class:`LearnedEgoPolicy` drives vehicle 0 with the same network (the paper's
non-vision ego), by default with its mean action.

Sampling (:mod:`avrisk.agents.drivers.sampling`): ``action_t = mean_t + c *
std_t * eps_t`` with standardised noise ``eps_t = rho eps_{t-1} + sqrt(1 -
rho^2) z_t``, ``z_t ~ N(0, 1)`` the simulator's noise (or, with
``noise_steps``, the innovations the parameter block carries after ``xi``:
columns of ``X``), ``rho = net.noise_correlation``
and ``c = net.noise_scale`` per action. With ``rho = 0`` and ``c = 1`` (the
paper) every step is an independent draw from the network's Gaussian. A fitted
``rho > 0`` keeps a Gaussian marginal at every step but makes the noise as
persistent as human residuals are (independent draws at 10 Hz give a jerk far
above human jerk); a calibrated ``c < 1`` tempers the variance that behaviour
cloning inflates on states it cannot predict. ``eps`` and ``xi`` are the
actor's state (:class:`LearnedState`) in the simulator loop.

Examples
--------
>>> import torch
>>> from avrisk.agents.drivers.network import DriverNet
>>> from avrisk.safety import MinTTC
>>> from avrisk.sim import Road, SimConfig, Simulator, VehicleState
>>> sim = Simulator(Road(n_lanes=3), SimConfig(horizon=0.5), measure=MinTTC())
>>> state = VehicleState.from_rows(
...     [[0.0, 5.55, 0.0, 20.0, 4.8, 1.9], [30.0, 5.55, 0.0, 18.0, 4.8, 1.9]]
... )
>>> net = DriverNet()
>>> driver = LearnedDriver(net, controlled=torch.tensor([True, True]))
>>> sim.run(state, [driver], torch.tensor([0])).steps.tolist()
[5]
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import torch
from pydantic import BaseModel, ConfigDict, Field
from torch import Tensor

from avrisk.agents.drivers.features import features_from_observation
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.network import ActionDistribution, DriverNet
from avrisk.agents.drivers.sampling import (
    DRIVER_NOISE_STREAM,
    EGO_NOISE_STREAM,
    ar1_noise,
    innovations_at,
    sample_actions,
)
from avrisk.agents.drivers.xi import XI_DIM
from avrisk.agents.policy import ego_only, register_policy
from avrisk.sim.interfaces import Action, NoiseRequest
from avrisk.sim.observation import Observation

__all__ = ["LearnedDriver", "LearnedEgoPolicy", "LearnedState"]


class LearnedState(NamedTuple):
    """Memory of a learned actor in the simulator loop.

    Attributes
    ----------
    xi : Tensor of shape (B, XI_DIM) or (XI_DIM,)
        Last layer of each rollout (or one for all), on the network's device
        and dtype.
    eps : Tensor of shape (B, ..., 2) or None
        Last step's standardised noise; None before the first step and
        without sampling.
    innovations : Tensor of shape (B, T, C, 2) or None
        Every step's innovations of the noise when they come with the
        parameter block (:class:`LearnedDriver` with ``noise_steps``), else
        None (the simulator draws them).
    """

    xi: Tensor
    eps: Tensor | None
    innovations: Tensor | None = None


def _as_xi(net: DriverNet, xi: Tensor | None) -> Tensor:
    """``xi`` (default ``net.default_xi``), checked, on the net's device and dtype."""
    xi = net.default_xi if xi is None else torch.as_tensor(xi)
    if xi.shape[-1] != XI_DIM or xi.dim() not in (1, 2):
        raise ValueError(
            f"xi must have shape (B, {XI_DIM}) or ({XI_DIM},); got {tuple(xi.shape)}"
        )
    return xi.to(net.input_mean.device, net.input_mean.dtype)


def _initial_state(
    name: str,
    net: DriverNet,
    default_xi: Tensor,
    params: Tensor | None,
    batch: int,
    noise: NoiseRequest | None,
) -> LearnedState:
    """The state at ``t = 0``: per-rollout ``xi`` from ``params``, else the default.

    ``eps`` is zero-filled when the actor samples (``noise``), so that its
    state has the same structure at every step (one compiled graph).
    """
    xi = default_xi if params is None else _as_xi(net, params)
    if xi.dim() == 2 and xi.shape[0] != batch:
        raise ValueError(
            f"{name} got xi for {xi.shape[0]} rollouts and a batch of {batch}; "
            f"pass xi of shape ({batch}, {XI_DIM})"
        )
    eps = None
    if noise is not None:
        eps = xi.new_zeros((batch, *noise.shape), dtype=noise.dtype)
    return LearnedState(xi=xi, eps=eps)


def _no_reverse(accel: Tensor, speed: Tensor, dt: float) -> Tensor:
    """Brake at most to a stop within the step (as the IDM drivers do)."""
    return torch.maximum(accel, speed * (-1.0 / dt))


class LearnedDriver:
    """Vehicles driven by the driver network, one ``xi`` per rollout (an actor).

    Parameters
    ----------
    net : DriverNet
        On the simulator's device.
    xi : Tensor of shape (B, XI_DIM) or (XI_DIM,), optional
        Last layer used when the simulator passes no parameter block
        (``params`` None in :meth:`init`): per rollout, or one for all;
        default ``net.default_xi``.
    controlled : Tensor of bool, shape (A,)
        The vehicles it drives. The network runs on these vehicles alone (one
        batched pass over their ``C`` columns); the others' actions it returns
        are zeros, to be replaced by their own actors'.
    stochastic : bool, default=True
        Sample the actions (the paper's generative model), with noise of
        shape (B, A, 2) drawn by the simulator; False drives with the mean
        actions (no noise).
    noise_steps : int or None, default=None
        Take the noise's innovations from the parameter block instead of the
        simulator: ``params`` of :meth:`init` is then ``xi`` followed by
        ``T = noise_steps`` steps of innovations, shape (B, XI_DIM + 2 T C)
        (:attr:`params_dim`; step-major, then the controlled vehicles in
        order, then acceleration and steering), so that they are columns of
        ``X``. Requires ``stochastic``.
    allow_reverse : bool, default=False
        False clips braking so that a vehicle stops rather than reverses
        within a step (speed noise around 0 in congested traffic would
        otherwise back cars up).
    guard : BrakeGuard, optional
        An emergency brake on the network's acceleration
        (:mod:`avrisk.agents.drivers.guard`); None (the default) drives on the
        network alone.
    """

    #: The features include every vehicle's lidar.
    reads_lidar = True

    def __init__(
        self,
        net: DriverNet,
        xi: Tensor | None = None,
        *,
        controlled: Tensor,
        stochastic: bool = True,
        noise_steps: int | None = None,
        allow_reverse: bool = False,
        guard: BrakeGuard | None = None,
    ) -> None:
        if noise_steps is not None and (not stochastic or noise_steps < 1):
            raise ValueError(
                "noise_steps (innovations in the parameter block) needs "
                f"stochastic=True and at least 1 step; got {noise_steps}"
            )
        self.net = net
        self.xi = _as_xi(net, xi)
        self.controlled = controlled
        # Columns of the controlled vehicles, or None for all of them (kept as
        # an index so the compiled step selects them without a host sync).
        self.columns = None if bool(controlled.all()) else controlled.nonzero()[:, 0]
        self.n_controlled = int(controlled.sum())
        self.stochastic = stochastic
        self.noise_steps = noise_steps
        self.allow_reverse = allow_reverse
        self.guard = guard
        self.noise = (
            NoiseRequest(
                DRIVER_NOISE_STREAM,
                (controlled.shape[0], 2),
                dtype=net.input_mean.dtype,
            )
            if stochastic and noise_steps is None
            else None
        )

    @property
    def params_dim(self) -> int:
        """Columns of the parameter block: ``XI_DIM``, plus ``2 T C`` innovations."""
        return XI_DIM + 2 * (self.noise_steps or 0) * self.n_controlled

    def init(self, obs: Observation, params: Tensor | None) -> LearnedState:
        """``xi`` of every rollout (``params``, shape (B, XI_DIM), or the default).

        With ``noise_steps``, ``params`` (B, :attr:`params_dim`) also holds
        the innovations, which the state keeps.

        Raises
        ------
        ValueError
            If ``xi`` has the wrong shape or another batch size than ``obs``,
            or the innovations are missing.
        """
        batch = obs.state.batch_size
        xi, innovations = params, None
        if self.noise_steps is not None:
            if (
                params is None
                or params.dim() != 2
                or params.shape[1] != self.params_dim
            ):
                got = None if params is None else tuple(params.shape)
                raise ValueError(
                    f"LearnedDriver with noise_steps={self.noise_steps} takes params "
                    f"of shape (B, {self.params_dim}) (xi, then the innovations); "
                    f"got {got}"
                )
            xi, innovations = params[:, :XI_DIM], params[:, XI_DIM:]
        state = _initial_state("LearnedDriver", self.net, self.xi, xi, batch, None)
        if not self.stochastic:
            return state
        if innovations is not None:
            innovations = innovations.to(state.xi.device, state.xi.dtype)
            innovations = innovations.reshape(batch, self.noise_steps, -1, 2)
            innovations = innovations.contiguous()
        # Zeros, so that the state has the same structure at every step.
        eps = state.xi.new_zeros((batch, self.n_controlled, 2))
        return LearnedState(state.xi, eps, innovations)

    def distribution(self, obs: Observation, xi: Tensor) -> ActionDistribution:
        """The controlled vehicles' action distributions, fields of shape (B, C).

        Their columns in vehicle order; ``C = A`` when it drives every vehicle.
        """
        return self.net(self._mine(features_from_observation(obs)), xi)

    def _guarded(self, accel: Tensor, obs: Observation) -> Tensor:
        """``accel`` (B, C) through the emergency brake, from the front beams."""
        assert self.guard is not None and obs.lidar is not None
        lidar = obs.lidar
        return self.guard.limit(
            accel,
            self._mine(lidar.range[..., 0]),
            self._mine(lidar.range_rate[..., 0]),
            self._mine(lidar.hit[..., 0]),
            self._mine(obs.state.length),
        )

    def _mine(self, t: Tensor) -> Tensor:
        """The controlled vehicles' columns of ``t``, shape (B, C, ...)."""
        return t if self.columns is None else t.index_select(1, self.columns)

    def _spread(self, t: Tensor) -> Tensor:
        """(B, C) values put in their columns of a (B, A) tensor, zeros elsewhere."""
        if self.columns is None:
            return t
        full = t.new_zeros(t.shape[0], self.controlled.shape[0])
        return full.index_copy(1, self.columns, t)

    def act(
        self, obs: Observation, state: LearnedState, noise: Tensor | None
    ) -> tuple[Action, LearnedState]:
        """Sampled (or mean) actions of every vehicle, fields of shape (B, A)."""
        dist = self.distribution(obs, state.xi)
        z = None  # the controlled vehicles' innovations, (B, C, 2)
        if state.innovations is not None:
            z = innovations_at(state.innovations, obs.step)
        elif noise is not None:
            z = self._mine(noise)
        eps = None
        if z is not None:
            rho = self.net.noise_correlation
            eps = ar1_noise(state.eps, z, rho, start=obs.step == 0)
        accel, steer = sample_actions(dist, eps, self.net.noise_scale)
        dtype = obs.state.x.dtype
        accel, steer = accel.to(dtype), steer.to(dtype)
        if self.guard is not None:
            accel = self._guarded(accel, obs)
        if not self.allow_reverse:
            accel = _no_reverse(accel, self._mine(obs.state.speed), obs.dt)
        action = Action(accel=self._spread(accel), steer=self._spread(steer))
        return action, LearnedState(state.xi, eps, state.innovations)


class LearnedEgoPolicy:
    """The lidar-based imitation ego: the driver network on vehicle 0 (an actor).

    Parameters
    ----------
    net : DriverNet
    n_vehicles : int
        ``A``; it controls vehicle 0.
    xi : Tensor of shape (XI_DIM,) or (B, XI_DIM), optional
        Used when the simulator passes no parameter block; default
        ``net.default_xi``.
    stochastic : bool, default=False
        An ego under test usually acts with its mean action; True samples it
        with noise of shape (B, 2).
    allow_reverse : bool, default=False
        See :class:`LearnedDriver`.
    range_scale : float, default=1.0
        Every lidar range the ego reads is multiplied by it: a miscalibrated
        sensor, for a variant of the ego to compare (``avrisk ab``). Above 1
        the gaps read longer than they are, so the ego brakes later.
    """

    #: The features include the ego's lidar.
    reads_lidar = True

    class Params(BaseModel):
        """``params`` of ``ego: {policy: lidar_imitation}`` (see the class)."""

        model_config = ConfigDict(frozen=True, extra="forbid")

        range_scale: float = Field(
            1.0,
            gt=0.0,
            description="Factor on every lidar range the ego reads (a "
            "miscalibrated sensor; above 1 it brakes later).",
        )

    def __init__(
        self,
        net: DriverNet,
        n_vehicles: int,
        xi: Tensor | None = None,
        *,
        stochastic: bool = False,
        allow_reverse: bool = False,
        range_scale: float = 1.0,
    ) -> None:
        self.net = net
        self.range_scale = float(range_scale)
        self.xi = _as_xi(net, xi)
        self.controlled = ego_only(n_vehicles, device=net.input_mean.device)
        self.stochastic = stochastic
        self.allow_reverse = allow_reverse
        self.noise = (
            NoiseRequest(EGO_NOISE_STREAM, (2,), dtype=net.input_mean.dtype)
            if stochastic
            else None
        )

    def init(self, obs: Observation, params: Tensor | None) -> LearnedState:
        """See :meth:`LearnedDriver.init`."""
        return _initial_state(
            "LearnedEgoPolicy",
            self.net,
            self.xi,
            params,
            obs.state.batch_size,
            self.noise,
        )

    def act(
        self, obs: Observation, state: LearnedState, noise: Tensor | None
    ) -> tuple[Action, LearnedState]:
        """The ego's action in every column, fields of shape (B, A)."""
        if self.range_scale != 1.0 and obs.lidar is not None:
            lidar = dataclasses.replace(
                obs.lidar, range=obs.lidar.range * self.range_scale
            )
            obs = dataclasses.replace(obs, lidar=lidar)
        feats = features_from_observation(obs)[:, :1]  # (B, 1, F)
        dist = self.net(feats, state.xi)[:, 0]
        eps = None
        if noise is not None:
            rho = self.net.noise_correlation
            eps = ar1_noise(state.eps, noise, rho, start=obs.step == 0)
        accel, steer = sample_actions(dist, eps, self.net.noise_scale)
        dtype = obs.state.x.dtype
        accel, steer = accel.to(dtype), steer.to(dtype)
        if not self.allow_reverse:
            accel = _no_reverse(accel, obs.state.speed[:, 0], obs.dt)
        shape = obs.state.shape
        return Action(
            accel=accel.unsqueeze(-1).expand(shape),
            steer=steer.unsqueeze(-1).expand(shape),
        ), LearnedState(state.xi, eps)


def _lidar_ego_factory(
    *, n_vehicles: int, net: DriverNet | None = None, range_scale: float = 1.0
) -> LearnedEgoPolicy:
    if net is None:
        from avrisk.agents.drivers.store import load_driver_net

        net = load_driver_net()
    return LearnedEgoPolicy(net, n_vehicles, range_scale=range_scale)


register_policy("lidar_imitation", _lidar_ego_factory, params=LearnedEgoPolicy.Params)
