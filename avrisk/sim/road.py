"""Road geometry: a straight multi-lane highway and its frame.

Frame
-----
``x`` [m] runs along the road from its start; ``y`` [m] is lateral, from the
*right* road edge, increasing to the left. Lane 0 is the rightmost lane; lane
``k`` has its centre at ``(k + 0.5) * lane_width``. The road edges are the
lines ``y = 0`` and ``y = n_lanes * lane_width``. Headings [rad] are measured
from ``+x``, counter-clockwise (a positive heading points to the left).

The simulator treats the road as unbounded along ``x`` (vehicles may drive past
``length``, which is for scenario placement and rendering) and bounded by its
two edges laterally; only straight roads are simulated, ``curvature`` is
carried so that driver features and later curved roads keep their interface.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["Road"]


@dataclass(frozen=True)
class Road:
    """A straight highway of equal-width lanes.

    Parameters
    ----------
    n_lanes : int, default=6
        Number of lanes, ``>= 1``.
    lane_width : float, default=3.7
        Width of every lane [m].
    length : float, default=500.0
        Length of the modelled stretch [m] (placement and rendering only).
    curvature : float, default=0.0
        Road curvature [1/m]; the simulator accepts only 0 (straight) for now.

    Examples
    --------
    >>> road = Road(n_lanes=3, lane_width=4.0)
    >>> road.width
    12.0
    >>> road.lane_center_y(2)
    10.0
    >>> road.lane_index(torch.tensor([0.5, 4.0, 11.9, 13.0])).tolist()
    [0, 1, 2, 2]
    """

    n_lanes: int = 6
    lane_width: float = 3.7  # [m]
    length: float = 500.0  # [m]
    curvature: float = 0.0  # [1/m]

    def __post_init__(self) -> None:
        if int(self.n_lanes) != self.n_lanes or self.n_lanes < 1:
            raise ValueError(
                f"n_lanes must be a positive integer; got {self.n_lanes!r}"
            )
        if not self.lane_width > 0:
            raise ValueError(f"lane_width must be > 0 [m]; got {self.lane_width!r}")
        if not self.length > 0:
            raise ValueError(f"length must be > 0 [m]; got {self.length!r}")

    @property
    def width(self) -> float:
        """Total width between the two road edges [m]."""
        return self.n_lanes * self.lane_width

    def lane_center_y(self, lane: Tensor | int) -> Tensor | float:
        """Lateral position of a lane's centre line.

        Parameters
        ----------
        lane : int or Tensor of int, shape (...)
            Lane index, 0 = rightmost.

        Returns
        -------
        float or Tensor of shape (...)
            ``(lane + 0.5) * lane_width`` [m].
        """
        return (lane + 0.5) * self.lane_width

    def lane_index(self, y: Tensor) -> Tensor:
        """Lane containing a lateral position, clamped to the road's lanes.

        Parameters
        ----------
        y : Tensor of shape (...)
            Lateral position [m]; positions beyond an edge map to the outer lane.

        Returns
        -------
        Tensor of int64, shape (...)
            Lane index in ``[0, n_lanes - 1]``.
        """
        lane = torch.floor(y / self.lane_width).to(torch.int64)
        return torch.clamp(lane, 0, self.n_lanes - 1)
