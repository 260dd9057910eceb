"""A pinhole camera on the ego: intrinsics, mount, and one ray per pixel.

Frames
------
The *ego frame* has ``x`` forward along the ego's heading, ``y`` to its left
and ``z`` up [m], origin on the ground below the ego's centre. The camera sits
at ``(forward, 0, height)`` in it, looks along the ego's heading and is pitched
down by ``pitch``; it does not roll.

Pixel ``(i, j)`` (row ``i`` from the top, column ``j`` from the left) looks
through its centre ``(j + 1/2, i + 1/2)`` in image coordinates; the principal
point is the image centre and pixels are square, with focal length
``f = (W / 2) / tan(hfov / 2)`` [pixels]. In the camera's own axes (forward
``F``, left ``L``, up ``U``) the pixel's ray is

    r = F + a L + b U,   a = -(j + 1/2 - W/2) / f,   b = -(i + 1/2 - H/2) / f,

scaled so that its forward component is 1: a point at ``camera + t r`` is at
depth ``t`` [m] along the optical axis (the z-buffer convention). With the
pitch ``p``, ``F = (cos p, 0, -sin p)`` and ``U = (sin p, 0, cos p)`` in the ego
frame. The horizon (rays with ``r_z = 0``) lies at ``b = tan p``, i.e. at image
row ``H/2 - f tan p`` (a row boundary there counts from the top edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["CameraModel", "PixelRays"]


@dataclass(frozen=True)
class PixelRays:
    """One ray per pixel in the ego frame, pixels in row-major order (``P = H W``).

    Attributes
    ----------
    x, y, z : Tensor of shape (P,)
        Ray direction in the ego frame, forward component along the optical
        axis 1 (see the module docstring).
    """

    x: Tensor  # [P]
    y: Tensor  # [P]
    z: Tensor  # [P]


@dataclass(frozen=True)
class CameraModel:
    """A front camera's intrinsics and its mount on the ego.

    Parameters
    ----------
    width, height : int, default=200, 66
        Image size ``W`` x ``H`` [pixels] (PilotNet's input).
    hfov : float, default=60.0
        Horizontal field of view [deg], in ``(0, 170)``.
    mount_height : float, default=1.4
        Height of the camera above the ground [m].
    pitch : float, default=5.0
        Downward pitch of the optical axis [deg], in ``(-45, 45)``.
    forward : float, default=1.0
        Position of the camera ahead of the ego's centre [m].

    Examples
    --------
    >>> cam = CameraModel(width=4, height=2, hfov=90.0, pitch=0.0)
    >>> round(cam.focal, 9)
    2.0
    >>> rays = cam.pixel_rays()
    >>> rays.y.tolist()[:4], rays.z.tolist()[::4]
    ([0.75, 0.25, -0.25, -0.75], [0.25, -0.25])
    """

    width: int = 200
    height: int = 66
    hfov: float = 60.0  # [deg]
    mount_height: float = 1.4  # [m]
    pitch: float = 5.0  # [deg]
    forward: float = 1.0  # [m]

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ValueError(
                f"image size must be >= 1 x 1 pixels; got {self.width} x {self.height}"
            )
        if not 0.0 < self.hfov < 170.0:
            raise ValueError(f"hfov must be in (0, 170) [deg]; got {self.hfov}")
        if not self.mount_height > 0.0:
            raise ValueError(f"mount_height must be > 0 [m]; got {self.mount_height}")
        if not -45.0 < self.pitch < 45.0:
            raise ValueError(f"pitch must be in (-45, 45) [deg]; got {self.pitch}")

    @property
    def focal(self) -> float:
        """Focal length ``f`` [pixels]."""
        return 0.5 * self.width / math.tan(math.radians(0.5 * self.hfov))

    @property
    def horizon_row(self) -> float:
        """Image row of the horizon, ``H/2 - f tan(pitch)`` (row boundaries integer)."""
        return 0.5 * self.height - self.focal * math.tan(math.radians(self.pitch))

    def pixel_rays(
        self, *, dtype: torch.dtype = torch.float32, device: str | torch.device = "cpu"
    ) -> PixelRays:
        """Every pixel's ray in the ego frame (computed in float64, then cast).

        Returns
        -------
        PixelRays
            Fields of shape (P,) with ``P = H W``, row-major.
        """
        f = self.focal
        cols = torch.arange(self.width, dtype=torch.float64) + 0.5
        rows = torch.arange(self.height, dtype=torch.float64) + 0.5
        a = (-(cols - 0.5 * self.width) / f).expand(self.height, -1).reshape(-1)
        b = (-(rows - 0.5 * self.height) / f).unsqueeze(-1).expand(-1, self.width)
        b = b.reshape(-1)
        p = math.radians(self.pitch)
        cp, sp = math.cos(p), math.sin(p)

        def out(t: Tensor) -> Tensor:
            return t.to(dtype=dtype, device=device).contiguous()

        return PixelRays(x=out(cp + b * sp), y=out(a), z=out(b * cp - sp))
