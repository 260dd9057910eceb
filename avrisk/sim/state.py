"""Batched vehicle state: every vehicle of every rollout as oriented rectangles."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from avrisk.sim.geometry import box_corners
from avrisk.tensors.mathops import sincos
from avrisk.tensors.tensors import TensorDataclass

__all__ = ["VehicleState"]


@dataclass(frozen=True)
class VehicleState(TensorDataclass):
    """Pose, speed and size of ``A`` vehicles in ``B`` rollouts.

    Every field is a floating tensor of shape (B, A) in road coordinates (see
    :mod:`avrisk.sim.road`); index 0 along ``A`` is the ego vehicle. A vehicle is
    a rectangle centred on ``(x, y)``, its long side along ``heading``. Its
    velocity points along its heading (the sensors ignore the bicycle model's
    small slip angle).

    Attributes
    ----------
    x : Tensor of shape (B, A)
        Centre position along the road [m].
    y : Tensor of shape (B, A)
        Centre position from the right road edge [m].
    heading : Tensor of shape (B, A)
        Heading from ``+x``, counter-clockwise [rad].
    speed : Tensor of shape (B, A)
        Signed speed along the heading [m/s]; negative is driving backwards.
    length : Tensor of shape (B, A)
        Length of the rectangle [m].
    width : Tensor of shape (B, A)
        Width of the rectangle [m].

    Examples
    --------
    >>> s = VehicleState.from_rows([[0.0, 0.0, 0.0, 20.0, 4.0, 2.0]])
    >>> s.shape, s.batch_size, s.n_vehicles
    (torch.Size([1, 1]), 1, 1)
    >>> s.corners[0, 0].tolist()
    [[2.0, 1.0], [-2.0, 1.0], [-2.0, -1.0], [2.0, -1.0]]
    """

    x: Tensor  # [B, A] m
    y: Tensor  # [B, A] m
    heading: Tensor  # [B, A] rad
    speed: Tensor  # [B, A] m/s
    length: Tensor  # [B, A] m
    width: Tensor  # [B, A] m

    @classmethod
    def from_rows(
        cls,
        rows: list[list[float]] | list[list[list[float]]],
        *,
        dtype: torch.dtype = torch.float32,
        device: str | torch.device = "cpu",
    ) -> VehicleState:
        """Build a state from nested lists ``[x, y, heading, speed, length, width]``.

        Parameters
        ----------
        rows : nested list of shape (A, 6) or (B, A, 6)
            One row per vehicle (units as the fields). A 2-level list is one
            rollout (``B = 1``).
        dtype : torch.dtype, default=torch.float32
        device : str or torch.device, default="cpu"

        Returns
        -------
        VehicleState
            Fields of shape (B, A).
        """
        t = torch.as_tensor(rows, dtype=dtype, device=device)
        if t.dim() == 2:
            t = t.unsqueeze(0)
        if t.dim() != 3 or t.shape[-1] != 6:
            raise ValueError(
                "rows must have shape (A, 6) or (B, A, 6) "
                f"[x, y, heading, speed, length, width]; got {tuple(t.shape)}"
            )
        return cls(*(t[..., k].contiguous() for k in range(6)))

    @property
    def batch_size(self) -> int:
        """Number of rollouts ``B``."""
        return self.x.shape[0]

    @property
    def n_vehicles(self) -> int:
        """Number of vehicles per rollout ``A`` (ego included)."""
        return self.x.shape[-1]

    @property
    def ego(self) -> VehicleState:
        """The ego vehicle alone: fields of shape (B, 1)."""
        return self[..., :1]

    @property
    def cos_sin(self) -> tuple[Tensor, Tensor]:
        """``cos(heading)``, ``sin(heading)``, each of shape (B, A) (reproducible)."""
        s, c = sincos(self.heading)
        return c, s

    @property
    def velocity(self) -> Tensor:
        """Velocity along the heading [m/s], shape (B, A, 2) as ``(vx, vy)``."""
        c, s = self.cos_sin
        return torch.stack([self.speed * c, self.speed * s], dim=-1)

    @property
    def corners(self) -> Tensor:
        """Rectangle corners [m], shape (B, A, 4, 2).

        Counter-clockwise from the front-left corner: front-left, rear-left,
        rear-right, front-right.
        """
        c, s = self.cos_sin
        return box_corners(self.x, self.y, c, s, 0.5 * self.length, 0.5 * self.width)

    def validate(self) -> VehicleState:
        """Check shapes, dtypes and values; return ``self`` for chaining.

        Raises
        ------
        ValueError
            If a field is not a floating tensor of the common shape (B, A) with
            ``B, A >= 1``, if a value is not finite, or if a size is not
            positive.
        """
        self._check_same_shape()
        for name, v in self._tensors().items():
            if not isinstance(v, Tensor) or not v.is_floating_point():
                raise ValueError(f"VehicleState.{name} must be a floating tensor")
            if v.device != self.x.device or v.dtype != self.x.dtype:
                raise ValueError(
                    f"VehicleState.{name} is {v.dtype} on {v.device}; every field must "
                    f"match x ({self.x.dtype} on {self.x.device})"
                )
            if not bool(torch.isfinite(v).all()):
                raise ValueError(f"VehicleState.{name} has non-finite values")
        if self.x.dim() != 2 or self.x.shape[0] < 1 or self.x.shape[1] < 1:
            raise ValueError(
                f"VehicleState fields must have shape (B, A) with B, A >= 1; "
                f"got {tuple(self.x.shape)}"
            )
        for name in ("length", "width"):
            if not bool((getattr(self, name) > 0).all()):
                raise ValueError(f"VehicleState.{name} must be > 0 [m] everywhere")
        return self
