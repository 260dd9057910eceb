"""Ray time-to-collision from the ego centre (paper, appendix A).

From the ego's centre, ``N`` rays are cast at angles ``2 pi i / N`` from its
heading. Ray ``i`` stops at the boundary of the first other vehicle it meets,
at distance ``s_i`` [m]; its range-rate ``ds_i`` [m/s] is that vehicle's
velocity relative to the ego projected on the ray. Then

    TTC_i = -s_i / ds_i   if ds_i < 0 (the hit vehicle approaches), else inf,
    TTC(t) = min_i TTC_i,
    f(X) = min over t = 0..T of TTC(t).

Road edges do not stop TTC rays (only vehicles are obstacles for TTC). The
distance runs from the ego *centre* to the other's *boundary*, so TTC is still
positive when the rectangles first intersect (a crash); the simulator stops a
rollout at its crash step, whose TTC counts. Velocities point along each
vehicle's heading (see :class:`~avrisk.sim.state.VehicleState`).

References
----------
.. [1] M. O'Kelly, A. Sinha, H. Namkoong, J. Duchi, R. Tedrake, "Scalable
   End-to-End Autonomous Vehicle Testing via Rare-event Simulation", NeurIPS
   2018, appendix A.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from avrisk.safety.running_min import RunningMin
from avrisk.sim.lidar import beam_directions, nearest_box, relative_velocity
from avrisk.sim.state import VehicleState

__all__ = ["MinTTC", "ray_ttc"]


def ray_ttc(
    state: VehicleState,
    cos: Tensor,
    sin: Tensor,
    ray_cos: Tensor,
    ray_sin: Tensor,
    max_range: float = math.inf,
) -> Tensor:
    """Instantaneous ray TTC between the ego (vehicle 0) and everyone else.

    Parameters
    ----------
    state : VehicleState
        Fields of shape (..., A); vehicle 0 is the ego.
    cos, sin : Tensor of shape (..., A)
        Cosine and sine of ``state.heading``.
    ray_cos, ray_sin : Tensor of shape (N,)
        Ray directions in the ego frame
        (:func:`avrisk.sim.lidar.beam_directions`).
    max_range : float, default=inf
        Vehicles farther than this along a ray [m] are not seen.

    Returns
    -------
    Tensor of shape (...)
        ``min_i TTC_i`` [s]; ``inf`` when no ray sees an approaching vehicle
        (or ``A == 1``).
    """
    if state.n_vehicles == 1:
        return torch.full_like(state.x[..., 0], math.inf)

    def ego(t: Tensor) -> Tensor:
        return t[..., :1]

    def rest(t: Tensor) -> Tensor:
        return t[..., 1:]

    s, j = nearest_box(
        ego(state.x),
        ego(state.y),
        ego(cos),
        ego(sin),
        rest(state.x),
        rest(state.y),
        rest(cos),
        rest(sin),
        0.5 * rest(state.length),
        0.5 * rest(state.width),
        ray_cos,
        ray_sin,
        max_range,
    )  # first vehicle on each ray, (..., N); inf: none
    wx, wy = relative_velocity(
        ego(cos), ego(sin), ego(state.speed), rest(cos), rest(sin), rest(state.speed)
    )
    # Closing rate -ds floored at zero: a receding or parallel vehicle gives
    # s / 0 = inf, and so does a ray that hits nothing (inf / anything). The
    # floor on s turns the one 0 / 0 (ego centre on a boundary, not closing)
    # into inf too, and abs() makes the inf positive whatever the zero's sign.
    closing = torch.clamp_min(
        wx.gather(-1, j) * -ray_cos - wy.gather(-1, j) * ray_sin, 0.0
    )
    ttc = torch.abs(torch.clamp_min(s, torch.finfo(s.dtype).tiny) / closing)
    return ttc.amin(dim=-1)


class MinTTC(RunningMin):
    """Safety measure ``f``: minimum ray TTC over rays and time [s].

    Parameters
    ----------
    n_rays : int, default=360
        Number of rays ``N`` cast from the ego centre.
    max_range : float, default=100.0
        Ray length [m]; vehicles beyond it are ignored (a TTC from there
        exceeds ``max_range / closing speed``, seconds, never a rare event).
    dtype : torch.dtype, default=torch.float32
    device : str or torch.device, default="cpu"

    Examples
    --------
    >>> from avrisk.sim.state import VehicleState
    >>> ego_and_lead = VehicleState.from_rows(
    ...     [[0.0, 0.0, 0.0, 20.0, 4.0, 2.0], [22.0, 0.0, 0.0, 10.0, 4.0, 2.0]]
    ... )
    >>> measure = MinTTC()
    >>> measure.instant(ego_and_lead).tolist()  # (22 - 2) m / (20 - 10) m/s
    [2.0]
    """

    name = "min_ttc"

    def __init__(
        self,
        n_rays: int = 360,
        max_range: float = 100.0,
        *,
        dtype: torch.dtype = torch.float32,
        device: str | torch.device = "cpu",
    ) -> None:
        if n_rays < 1:
            raise ValueError(f"n_rays must be >= 1; got {n_rays}")
        if not max_range > 0:
            raise ValueError(f"max_range must be > 0 [m]; got {max_range}")
        self.n_rays = n_rays
        #: Ray-box tests per (ego, other) pair and instant (sizes eager slices).
        self.tests_per_pair = n_rays
        self.max_range = max_range
        self.ray_cos, self.ray_sin = beam_directions(n_rays, dtype=dtype, device=device)

    def instant(
        self, state: VehicleState, cos: Tensor | None = None, sin: Tensor | None = None
    ) -> Tensor:
        """TTC at one instant [s], shape (...) for a state of shape (..., A).

        ``cos``/``sin`` of the headings may be passed when already computed.
        """
        if cos is None or sin is None:
            cos, sin = state.cos_sin
        ray_cos = self.ray_cos.to(device=state.x.device, dtype=state.x.dtype)
        ray_sin = self.ray_sin.to(device=state.x.device, dtype=state.x.dtype)
        return ray_ttc(state, cos, sin, ray_cos, ray_sin, self.max_range)
