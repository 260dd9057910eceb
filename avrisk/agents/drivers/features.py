"""The learned drivers' input features: one layout, one assembly function.

Paper, appendix B (after Kuefler et al. 2017): a driver sees its own size and
motion relative to its lane, three indicator flags and a 20-beam lidar. The
layout below is *the* definition; every producer of driver inputs (the
simulator's observations, the NGSIM demonstrations, the realism benchmark)
goes through :func:`assemble_features`, and :func:`features_from_observation`
is the only way the simulator's observation is turned into network inputs.

======  ======================  ======  ===========================================
index   name                    unit    meaning
======  ======================  ======  ===========================================
0       ``length``              m       vehicle length
1       ``width``               m       vehicle width
2       ``speed``               m/s     signed speed along the heading
3       ``lateral_offset``      m       centre minus lane centre, positive left
4       ``heading_offset``      rad     heading minus lane heading, ccw positive
5       ``left_marking``        m       centre to the lane's left boundary
6       ``right_marking``       m       centre to the lane's right boundary
7       ``curvature``           1/m     lane curvature at the vehicle
8       ``collided``            -       1 if overlapping another vehicle, else 0
9       ``offroad``             -       1 if a corner is beyond a road edge
10      ``reversing``           -       1 if moving against the road direction
11..30  ``range_k``             m       lidar range of beam ``k`` (``k = 0..19``)
31..50  ``range_rate_k``        m/s     lidar range-rate of beam ``k``
======  ======================  ======  ===========================================

Beam ``k`` points ``2 pi k / R`` counter-clockwise from the heading (beam 0
straight ahead); see :mod:`avrisk.sim.lidar`. A beam that hits nothing reads
the lidar range (or the distance to a road edge) and range-rate 0.

Examples
--------
>>> N_FEATURES, FEATURE_NAMES[:3], FEATURE_UNITS["range_rate_0"]
(51, ('length', 'width', 'speed'), 'm/s')
>>> FEATURE_INDEX["range_0"], FEATURE_INDEX["range_rate_0"]
(11, 31)
"""

from __future__ import annotations

import torch
from torch import Tensor

from avrisk.sim.observation import Observation

__all__ = [
    "FEATURE_INDEX",
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "INDICATOR_FEATURES",
    "N_BEAMS",
    "N_FEATURES",
    "N_SCALAR_FEATURES",
    "assemble_features",
    "features_from_observation",
]

#: Lidar beams of the driver network ``R`` (paper, appendix B).
N_BEAMS = 20

_SCALARS: tuple[tuple[str, str], ...] = (
    ("length", "m"),
    ("width", "m"),
    ("speed", "m/s"),
    ("lateral_offset", "m"),
    ("heading_offset", "rad"),
    ("left_marking", "m"),
    ("right_marking", "m"),
    ("curvature", "1/m"),
    ("collided", "-"),
    ("offroad", "-"),
    ("reversing", "-"),
)

#: Number of non-lidar features (11).
N_SCALAR_FEATURES = len(_SCALARS)

#: Feature names in input order, length ``N_FEATURES``.
FEATURE_NAMES: tuple[str, ...] = (
    *(name for name, _ in _SCALARS),
    *(f"range_{k}" for k in range(N_BEAMS)),
    *(f"range_rate_{k}" for k in range(N_BEAMS)),
)

#: Unit of every feature, by name.
FEATURE_UNITS: dict[str, str] = {
    **dict(_SCALARS),
    **{f"range_{k}": "m" for k in range(N_BEAMS)},
    **{f"range_rate_{k}": "m/s" for k in range(N_BEAMS)},
}

#: Position of every feature, by name.
FEATURE_INDEX: dict[str, int] = {name: i for i, name in enumerate(FEATURE_NAMES)}

#: The 0/1 indicator features (not standardised by the network).
INDICATOR_FEATURES: tuple[str, ...] = ("collided", "offroad", "reversing")

#: Number of inputs of the driver network (11 + 2 R = 51).
N_FEATURES = len(FEATURE_NAMES)


def assemble_features(
    *,
    length: Tensor,
    width: Tensor,
    speed: Tensor,
    lateral_offset: Tensor,
    heading_offset: Tensor,
    left_marking: Tensor,
    right_marking: Tensor,
    curvature: Tensor,
    collided: Tensor,
    offroad: Tensor,
    reversing: Tensor,
    lidar_range: Tensor,
    lidar_range_rate: Tensor,
) -> Tensor:
    """Stack the named quantities into the network's input layout.

    Parameters
    ----------
    length, width, speed, lateral_offset, heading_offset, left_marking, \
right_marking, curvature : Tensor of shape (...)
        Floating tensors, units as in the module table.
    collided, offroad, reversing : Tensor of shape (...)
        Boolean or 0/1 indicators.
    lidar_range : Tensor of shape (..., R)
        Ranges [m] of ``R = N_BEAMS`` beams.
    lidar_range_rate : Tensor of shape (..., R)
        Range-rates [m/s].

    Returns
    -------
    Tensor of shape (..., N_FEATURES)
        In the dtype of ``speed``.

    Raises
    ------
    ValueError
        If the lidar does not have ``N_BEAMS`` beams.
    """
    if lidar_range.shape[-1] != N_BEAMS or lidar_range_rate.shape[-1] != N_BEAMS:
        raise ValueError(
            f"the driver network takes {N_BEAMS} lidar beams; got ranges of shape "
            f"{tuple(lidar_range.shape)} and range-rates of shape "
            f"{tuple(lidar_range_rate.shape)} (set n_lidar_beams: {N_BEAMS})"
        )
    dtype = speed.dtype
    scalars = torch.stack(
        [
            length.to(dtype),
            width.to(dtype),
            speed,
            lateral_offset.to(dtype),
            heading_offset.to(dtype),
            left_marking.to(dtype),
            right_marking.to(dtype),
            curvature.to(dtype),
            collided.to(dtype),
            offroad.to(dtype),
            reversing.to(dtype),
        ],
        dim=-1,
    )
    return torch.cat([scalars, lidar_range.to(dtype), lidar_range_rate.to(dtype)], -1)


def features_from_observation(obs: Observation) -> Tensor:
    """Driver-network inputs of every vehicle in a simulator observation.

    Parameters
    ----------
    obs : Observation
        With a lidar of ``N_BEAMS`` beams; fields of shape (B, A).

    Returns
    -------
    Tensor of shape (B, A, N_FEATURES)

    Raises
    ------
    ValueError
        If the observation has no lidar or the wrong number of beams.
    """
    if obs.lidar is None:
        raise ValueError(
            f"learned drivers need lidar; simulate with n_lidar_beams={N_BEAMS}"
        )
    s, lane = obs.state, obs.lane
    return assemble_features(
        length=s.length,
        width=s.width,
        speed=s.speed,
        lateral_offset=lane.lateral_offset,
        heading_offset=lane.heading_offset,
        left_marking=lane.left_marking,
        right_marking=lane.right_marking,
        curvature=lane.curvature,
        collided=obs.collided,
        offroad=obs.offroad,
        reversing=obs.reversing,
        lidar_range=obs.lidar.range,
        lidar_range_rate=obs.lidar.range_rate,
    )
