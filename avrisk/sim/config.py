"""A simulator's settings: time step, horizon, lidar, physical limits, compiling.

:class:`SimConfig` holds what a scenario sets; whether the step is compiled
(``torch.compile``) is the simulator's own argument, defaulting to the
environment variable :data:`COMPILE_ENV` (:func:`compile_requested`), so that
a command line or a benchmark can switch it on without code changes.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from avrisk.sim.dynamics import BicycleLimits

__all__ = ["COMPILE_ENV", "SimConfig", "compile_requested"]

#: Environment variable that switches ``torch.compile`` on when ``Simulator``
#: is built with ``compile=None`` (the default).
COMPILE_ENV = "AVRISK_COMPILE"


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Parameters
    ----------
    dt : float, default=0.1
        Time step [s].
    horizon : float, default=10.0
        Simulated time [s]; ``T = ceil(horizon / dt)`` steps.
    n_lidar_beams : int, default=20
        Beams per vehicle lidar ``R``; 0 disables lidar.
    lidar_range : float, default=50.0
        Lidar range [m].
    accel_min, accel_max : float, default=-9.0, 6.0
        Physical acceleration limits [m/s^2].
    max_steer : float, default=0.6
        Physical front-wheel angle limit [rad].
    min_speed, max_speed : float, default=-10.0, 45.0
        Physical speed limits [m/s] (negative is reverse).
    wheelbase_fraction : float, default=0.6
        Wheelbase over vehicle length [-].
    """

    dt: float = 0.1  # [s]
    horizon: float = 10.0  # [s]
    n_lidar_beams: int = 20
    lidar_range: float = 50.0  # [m]
    accel_min: float = -9.0  # [m/s^2]
    accel_max: float = 6.0  # [m/s^2]
    max_steer: float = 0.6  # [rad]
    min_speed: float = -10.0  # [m/s]
    max_speed: float = 45.0  # [m/s]
    wheelbase_fraction: float = 0.6  # [-]

    def __post_init__(self) -> None:
        if not self.dt > 0:
            raise ValueError(f"dt must be > 0 [s]; got {self.dt}")
        if not self.horizon >= 0:
            raise ValueError(f"horizon must be >= 0 [s]; got {self.horizon}")
        if self.n_lidar_beams < 0:
            raise ValueError(f"n_lidar_beams must be >= 0; got {self.n_lidar_beams}")
        if not self.lidar_range > 0:
            raise ValueError(f"lidar_range must be > 0 [m]; got {self.lidar_range}")
        self.limits  # noqa: B018  (validates the physical limits)

    @property
    def n_steps(self) -> int:
        """Number of steps ``T`` of a full rollout."""
        return math.ceil(self.horizon / self.dt - 1e-9)

    @property
    def limits(self) -> BicycleLimits:
        """The physical limits as the bicycle model takes them."""
        return BicycleLimits(
            accel_min=self.accel_min,
            accel_max=self.accel_max,
            max_steer=self.max_steer,
            min_speed=self.min_speed,
            max_speed=self.max_speed,
            wheelbase_fraction=self.wheelbase_fraction,
        )


def compile_requested(compile: bool | None) -> bool:
    """Whether a simulator compiles: ``compile``, or if None, ``AVRISK_COMPILE``.

    Parameters
    ----------
    compile : bool or None

    Returns
    -------
    bool
        ``compile`` when given; for None, whether the environment variable
        ``AVRISK_COMPILE`` is ``1``, ``true`` or ``yes``.
    """
    if compile is None:
        flag = os.environ.get(COMPILE_ENV, "0").strip().lower()
        return flag in ("1", "true", "yes")
    return bool(compile)
