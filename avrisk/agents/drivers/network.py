"""The driver network: 51 features -> 200 -> 100 -> Gaussian over (accel, steer).

Architecture (paper, appendix B, after Kuefler et al. 2017)::

    z   = (features - input_mean) / input_scale                 (..., 51)
    h1  = relu(W1 z + b1)                                        (..., 200)
    h   = relu(W2 h1 + b2)                                       (..., 100)  trunk
    out = W h + b,   (W, b) = unpack_xi(xi)                      (..., 4)    head
    accel ~ N(s_a out[0], s_a^2 exp(out[2]))                     [m/s^2]
    steer ~ N(s_s out[1], s_s^2 exp(out[3]))                     [rad]

``s_a, s_s`` (``action_scale``) put both actions on a unit scale so that one
``xi`` perturbation means about as much for steering as for acceleration; the
log-variances are clipped to ``[LOG_VAR_MIN, LOG_VAR_MAX]`` in that scale.
That is the ``"free"`` head. With ``head="idm"`` the mean acceleration is the
Intelligent Driver Model's instead, ``out[0]`` scaling the gap it keeps
(:mod:`avrisk.agents.drivers.idm_head`); the rest is the same.

The trunk is shared; the last layer is ``xi`` (:mod:`avrisk.agents.drivers.xi`),
and :meth:`DriverNet.head` evaluates a *different* ``xi`` per rollout in one
batched product (``torch.bmm``), with no Python loop over rollouts.

Batch independence
------------------
A rollout's outputs must not depend on the batch it shares (see
:mod:`avrisk.sim.interfaces`). Elementwise operations and ReLU are exact; a
matrix product is not automatically: BLAS picks different kernels for very
few rows (on MKL, fewer than 12 rows that are not a multiple of 4 give
results that differ in the last bit). :func:`row_linear` therefore pads the
rows of every trunk product to a multiple of :data:`ROW_BLOCK`, so every row
takes the same kernel whatever the batch size; the per-rollout ``bmm`` of the
head is a product per rollout and is batch independent as it is. The tests
check bit equality alone, in a batch and permuted. Across machines (another
CPU's instruction set, a GPU) results may differ in the last bits, as any
BLAS result does.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from avrisk.agents.drivers.features import FEATURE_NAMES, N_FEATURES
from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.agents.drivers.idm_head import IDMHead, check_head
from avrisk.agents.drivers.xi import (
    N_HIDDEN_LAST,
    N_OUTPUTS,
    XI_DIM,
    pack_xi,
    unpack_xi,
)
from avrisk.tensors.mathops import log
from avrisk.tensors.tensors import TensorDataclass

__all__ = [
    "FORMAT_VERSION",
    "HIDDEN_SIZES",
    "LOG_VAR_MAX",
    "LOG_VAR_MIN",
    "ROW_BLOCK",
    "ActionDistribution",
    "DriverNet",
    "row_linear",
]

#: Hidden layer widths (paper, appendix B).
HIDDEN_SIZES = (200, N_HIDDEN_LAST)

#: Clip of the log-variances, in the standardised action scale [-].
LOG_VAR_MIN, LOG_VAR_MAX = -12.0, 4.0

#: Trunk products run on a multiple of this many rows (batch independence).
ROW_BLOCK = 16

#: Version of the ``.npz`` weight format written by :meth:`DriverNet.save`.
FORMAT_VERSION = 1


def row_linear(x: Tensor, weight: Tensor, bias: Tensor | None = None) -> Tensor:
    """``x W^T + b`` whose rows do not depend on how many rows there are.

    Parameters
    ----------
    x : Tensor of shape (..., K)
    weight : Tensor of shape (N, K)
    bias : Tensor of shape (N,) or None

    Returns
    -------
    Tensor of shape (..., N)
        Row ``i`` is bit-identical to the same row computed in any other batch
        (on one machine): the rows are zero-padded to a multiple of
        :data:`ROW_BLOCK` so that the BLAS kernel is always the same.
    """
    rows = x.reshape(-1, x.shape[-1])
    n = rows.shape[0]
    pad = (-n) % ROW_BLOCK if n >= ROW_BLOCK else ROW_BLOCK - n
    if pad:
        rows = F.pad(rows, (0, 0, 0, pad))
    out = F.linear(rows, weight, bias)[:n]
    return out.reshape(*x.shape[:-1], weight.shape[0])


@dataclass(frozen=True)
class ActionDistribution(TensorDataclass):
    """Independent Gaussians over acceleration and steering, per vehicle.

    Attributes
    ----------
    accel_mean : Tensor of shape (...)
        Mean acceleration [m/s^2].
    steer_mean : Tensor of shape (...)
        Mean front-wheel angle [rad].
    accel_log_var : Tensor of shape (...)
        Log-variance of the acceleration [log (m/s^2)^2].
    steer_log_var : Tensor of shape (...)
        Log-variance of the steering [log rad^2].
    """

    accel_mean: Tensor  # [...] m/s^2
    steer_mean: Tensor  # [...] rad
    accel_log_var: Tensor  # [...] log (m/s^2)^2
    steer_log_var: Tensor  # [...] log rad^2

    def log_prob(self, accel: Tensor, steer: Tensor) -> tuple[Tensor, Tensor]:
        """Gaussian log-densities of observed actions.

        Parameters
        ----------
        accel : Tensor of shape (...)
            Acceleration [m/s^2].
        steer : Tensor of shape (...)
            Steering [rad].

        Returns
        -------
        log_p_accel, log_p_steer : Tensor of shape (...)
            [log 1/(m/s^2)] and [log 1/rad].
        """
        half_log_2pi = 0.5 * math.log(2 * math.pi)

        def lp(x: Tensor, mean: Tensor, log_var: Tensor) -> Tensor:
            return -0.5 * (log_var + (x - mean) ** 2 * torch.exp(-log_var)) - (
                half_log_2pi
            )

        return (
            lp(accel, self.accel_mean, self.accel_log_var),
            lp(steer, self.steer_mean, self.steer_log_var),
        )


class DriverNet(nn.Module):
    """The driver network with a shared trunk and a replaceable last layer.

    Parameters
    ----------
    input_mean : array_like of shape (N_FEATURES,), optional
        Feature centring [feature units]; default 0.
    input_scale : array_like of shape (N_FEATURES,), optional
        Feature scaling [feature units]; default 1. Must be positive.
    action_scale : tuple of float, default=(1.0, 0.02)
        ``(s_a [m/s^2], s_s [rad])``: output unit of the two means.
    noise_correlation : tuple of float, default=(0.0, 0.0)
        Per-step autocorrelation ``rho`` in ``[0, 1)`` of the standardised
        action noise (acceleration, steering) when actions are sampled in
        closed loop (:class:`~avrisk.agents.drivers.driver.LearnedDriver`); 0
        draws independent noise every step (the paper's sampling). Fitted to
        the human residuals by :func:`avrisk.learning.training.train.train_drivers`.
    noise_scale : tuple of float, default=(1.0, 1.0)
        Factor on the standard deviations when actions are sampled in closed
        loop, per action, ``>= 0`` (1: the network's own Gaussian; 0: its mean).
        Calibrated on closed-loop replays of human training episodes by
        :func:`avrisk.learning.training.train.train_drivers`.
    guard : BrakeGuard, optional
        The emergency brake these drivers are meant to drive with
        (:mod:`avrisk.agents.drivers.guard`); saved with the weights. The
        network does not apply it: a
        :class:`~avrisk.agents.drivers.driver.LearnedDriver` does, when given
        it (the scenarios' environment drivers and ``avrisk realism`` are).
    head : {"free", "idm"}, default="free"
        What the first output means: the mean acceleration, or the log factor
        on the IDM's desired gap (:mod:`avrisk.agents.drivers.idm_head`).

    Attributes
    ----------
    fc1 : torch.nn.Linear
        51 -> 200.
    fc2 : torch.nn.Linear
        200 -> 100.
    last : torch.nn.Linear
        100 -> 4: the default ``xi`` (the trained shared head).
    idm : IDMHead or None
        The IDM's shared parameters of an ``"idm"`` head; None for ``"free"``.

    Examples
    --------
    >>> import torch
    >>> net = DriverNet()
    >>> feats = torch.zeros(3, 6, N_FEATURES)          # (B, A, 51)
    >>> xi = net.default_xi.expand(3, XI_DIM)          # (B, 404): one per rollout
    >>> net(feats, xi).accel_mean.shape
    torch.Size([3, 6])
    """

    def __init__(
        self,
        input_mean: Any = None,
        input_scale: Any = None,
        action_scale: tuple[float, float] = (1.0, 0.02),
        noise_correlation: tuple[float, float] = (0.0, 0.0),
        noise_scale: tuple[float, float] = (1.0, 1.0),
        guard: BrakeGuard | None = None,
        head: str = "free",
    ) -> None:
        super().__init__()
        self.guard = guard
        self.idm = IDMHead() if check_head(head) == "idm" else None
        mean = torch.zeros(N_FEATURES) if input_mean is None else _vec(input_mean)
        scale = torch.ones(N_FEATURES) if input_scale is None else _vec(input_scale)
        if mean.shape != (N_FEATURES,) or scale.shape != (N_FEATURES,):
            raise ValueError(
                f"input_mean and input_scale must have shape ({N_FEATURES},); got "
                f"{tuple(mean.shape)} and {tuple(scale.shape)}"
            )
        if not bool((scale > 0).all()):
            raise ValueError("input_scale must be positive everywhere")
        act = _vec(action_scale)
        if act.shape != (2,) or not bool((act > 0).all()):
            raise ValueError(
                f"action_scale must be two positive numbers; got {action_scale}"
            )
        self.register_buffer("input_mean", mean)
        self.register_buffer("input_scale", scale)
        rho = _vec(noise_correlation)
        if rho.shape != (2,) or not bool(((rho >= 0) & (rho < 1)).all()):
            raise ValueError(
                "noise_correlation must be two numbers in [0, 1); got "
                f"{noise_correlation}"
            )
        temp = _vec(noise_scale)
        if temp.shape != (2,) or not bool((temp >= 0).all()):
            raise ValueError(f"noise_scale must be two numbers >= 0; got {noise_scale}")
        self.register_buffer("action_scale", act)
        self.register_buffer("noise_correlation", rho)
        self.register_buffer("noise_scale", temp)
        self.fc1 = nn.Linear(N_FEATURES, HIDDEN_SIZES[0])
        self.fc2 = nn.Linear(HIDDEN_SIZES[0], HIDDEN_SIZES[1])
        self.last = nn.Linear(N_HIDDEN_LAST, N_OUTPUTS)
        # 2 log(action_scale), a constant of every step: computed once here and
        # again whenever the buffers change (load_state_dict, to()).
        self.register_buffer("log_action_var", 2.0 * log(act), persistent=False)
        self.register_load_state_dict_post_hook(
            lambda module, _keys: module._refresh_log_action_var()
        )

    def _refresh_log_action_var(self) -> None:
        with torch.no_grad():
            self.log_action_var = 2.0 * log(self.action_scale)

    def _apply(self, fn: Any, recurse: bool = True) -> DriverNet:
        out = super()._apply(fn, recurse)
        self._refresh_log_action_var()  # in the new dtype, as before the move
        return out

    # ---------------------------------------------------------------- layers
    @property
    def default_xi(self) -> Tensor:
        """The trained shared head as ``xi``, shape (XI_DIM,) (no gradient)."""
        return pack_xi(self.last.weight.detach(), self.last.bias.detach())

    def trunk(self, features: Tensor) -> Tensor:
        """Hidden representation shared by every ``xi``.

        Parameters
        ----------
        features : Tensor of shape (..., N_FEATURES)

        Returns
        -------
        Tensor of shape (..., 100)
        """
        z = (features.to(self.input_mean.dtype) - self.input_mean) / self.input_scale
        # In place: each product's output is fresh, so the ReLU writes no new
        # buffer (at large batches a new one costs more than the ReLU itself).
        h = torch.relu_(row_linear(z, self.fc1.weight, self.fc1.bias))
        return torch.relu_(row_linear(h, self.fc2.weight, self.fc2.bias))

    def head(self, hidden: Tensor, xi: Tensor | None = None) -> Tensor:
        """Last layer: raw outputs from hidden units.

        Parameters
        ----------
        hidden : Tensor of shape (B, ..., 100)
        xi : Tensor of shape (XI_DIM,) or (B, XI_DIM), optional
            One last layer for all rows, or one per leading index ``b`` (per
            rollout); default :attr:`default_xi` (with gradient to ``last``).

        Returns
        -------
        Tensor of shape (B, ..., 4)
            Standardised means and log-variances (:data:`OUTPUT_NAMES` order).
        """
        if xi is None:
            return row_linear(hidden, self.last.weight, self.last.bias)
        xi = xi.to(hidden.dtype)
        weight, bias = unpack_xi(xi)
        if xi.dim() == 1:
            return row_linear(hidden, weight, bias)
        if xi.dim() != 2 or xi.shape[0] != hidden.shape[0]:
            raise ValueError(
                f"per-rollout xi must have shape ({hidden.shape[0]}, {XI_DIM}) to "
                f"match hidden of shape {tuple(hidden.shape)}; got {tuple(xi.shape)}"
            )
        rows = hidden.reshape(hidden.shape[0], -1, N_HIDDEN_LAST)  # (B, K, 100)
        out = torch.bmm(rows, weight.transpose(1, 2)) + bias.unsqueeze(1)
        return out.reshape(*hidden.shape[:-1], N_OUTPUTS)

    @property
    def head_kind(self) -> str:
        """``"idm"`` or ``"free"``: what the first output means (class doc)."""
        return "free" if self.idm is None else "idm"

    def distribution(
        self, raw: Tensor, features: Tensor | None = None
    ) -> ActionDistribution:
        """Physical Gaussian parameters from raw head outputs.

        Parameters
        ----------
        raw : Tensor of shape (..., 4)
        features : Tensor of shape (..., N_FEATURES), optional
            The unscaled features the outputs came from, broadcastable
            against ``raw``'s leading shape; needed by an ``"idm"`` head,
            whose mean acceleration depends on the gap ahead.

        Returns
        -------
        ActionDistribution
            Fields of shape (...).

        Raises
        ------
        ValueError
            If the head is ``"idm"`` and ``features`` is None.
        """
        s = self.action_scale.to(raw.dtype)
        offset = self.log_action_var
        if offset.dtype != raw.dtype:
            offset = 2.0 * log(s)
        log_var = torch.clamp(raw[..., 2:], LOG_VAR_MIN, LOG_VAR_MAX) + offset
        if self.idm is None:
            accel_mean = raw[..., 0] * s[0]
        elif features is None:
            raise ValueError("an 'idm' head needs the features for its acceleration")
        else:
            accel_mean = self.idm.mean_accel(raw[..., 0], features)
        return ActionDistribution(
            accel_mean=accel_mean,
            steer_mean=raw[..., 1] * s[1],
            accel_log_var=log_var[..., 0],
            steer_log_var=log_var[..., 1],
        )

    def forward(self, features: Tensor, xi: Tensor | None = None) -> ActionDistribution:
        """Action distribution of every vehicle.

        Parameters
        ----------
        features : Tensor of shape (B, ..., N_FEATURES)
            Laid out as in :mod:`avrisk.agents.drivers.features`.
        xi : Tensor of shape (XI_DIM,) or (B, XI_DIM), optional
            See :meth:`head`.

        Returns
        -------
        ActionDistribution
            Fields of shape (B, ...).
        """
        return self.distribution(self.head(self.trunk(features), xi), features)

    # --------------------------------------------------------- serialisation
    def to_arrays(self) -> dict[str, np.ndarray]:
        """Every parameter and buffer as float32 numpy arrays, plus metadata."""
        arrays = {
            k: v.detach().cpu().to(torch.float32).numpy()
            for k, v in self.state_dict().items()
        }
        meta = {
            "format_version": FORMAT_VERSION,
            "features": list(FEATURE_NAMES),
            "hidden_sizes": list(HIDDEN_SIZES),
            "xi_dim": XI_DIM,
        }
        if self.guard is not None:
            meta["guard"] = self.guard.to_dict()
        if self.idm is not None:
            meta["head"] = self.head_kind
        arrays["meta"] = np.array(json.dumps(meta))
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> DriverNet:
        """Rebuild a network saved by :meth:`to_arrays`.

        Raises
        ------
        ValueError
            If the format version or the feature layout differs from this
            code's, or the saved guard or head is malformed.
        """
        meta = json.loads(str(arrays["meta"]))
        if meta.get("format_version") != FORMAT_VERSION:
            raise ValueError(
                f"driver weights have format {meta.get('format_version')}, this "
                f"code reads {FORMAT_VERSION}; retrain with train_drivers()"
            )
        if tuple(meta.get("features", ())) != FEATURE_NAMES:
            raise ValueError("driver weights were trained on another feature layout")
        net = cls(
            arrays["input_mean"],
            arrays["input_scale"],
            tuple(arrays["action_scale"]),
            tuple(arrays["noise_correlation"]),
            tuple(arrays["noise_scale"]),
            guard=None if "guard" not in meta else BrakeGuard.from_dict(meta["guard"]),
            head=meta.get("head", "free"),
        )
        state = {k: torch.from_numpy(np.asarray(arrays[k])) for k in net.state_dict()}
        net.load_state_dict(state)
        return net

    def save(self, path: str | Path) -> None:
        """Write the weights as an uncompressed ``.npz`` (no pickle)."""
        np.savez(Path(path), **self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> DriverNet:
        """Read weights written by :meth:`save` (``allow_pickle=False``)."""
        with np.load(Path(path), allow_pickle=False) as data:
            return cls.from_arrays({k: data[k] for k in data.files})


def _vec(x: Any) -> Tensor:
    return torch.as_tensor(np.asarray(x, dtype=np.float32)).reshape(-1)
