"""An emergency brake on top of the learned drivers: kinematic, rarely engaged.

The closed-loop trainings that keep gaps as short as the humans' (gap 5th
percentile within a few per cent) still rear-end stopping queues in some
held-out windows: they brake too late and too gently when the closing speed
is high for the gap left (BENCHMARKS.md "Learned drivers"). A driver here can
carry a :class:`BrakeGuard`: from its front lidar beam (beam 0, along its
heading) it takes the bumper gap ``g = range - length / 2`` to the vehicle
that beam hits and the closing speed ``c = max(-range_rate, 0)``; the
constant deceleration that ends the closing ``gap_floor`` short of that
vehicle is ``d = c^2 / (2 max(g - gap_floor, 0.1 m))``. Where ``d`` exceeds
``engage_decel`` the acceleration is ``min(network's, -d)``; elsewhere the
network's is unchanged, bit for bit. In ordinary following ``d`` is small
and the guard does nothing; in the held-out replays of BENCHMARKS.md ("An
emergency brake on the learned drivers", floors of 1-2 m) it engaged in
0.15-0.36% of the vehicle-steps, and moved no distribution by more than
0.003 in KS.

With ``hold_floor`` the guard also acts wherever the gap is already inside
the floor (``g < gap_floor``) and closing (``c > 0``), whatever ``d``: a
slow creep into a standing queue (``c`` under about 0.6 m/s for a floor of
2 m and ``engage_decel = 2``) never needs more than ``engage_decel`` and
would otherwise reach the vehicle ahead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["BrakeGuard", "parse_guard"]

#: Smallest distance [m] left before the floor in the deceleration's divisor.
_MIN_ROOM = 0.1


@dataclass(frozen=True)
class BrakeGuard:
    """The emergency brake's two settings.

    Parameters
    ----------
    gap_floor : float
        Bumper gap [m] at which the closing should end, ``>= 0``.
    engage_decel : float
        Deceleration [m/s^2] needed before the guard acts, ``> 0``.
    hold_floor : bool, default=False
        Also act wherever the gap is inside ``gap_floor`` and closing. False
        is the guard of the files written before this setting existed (their
        metadata has no ``hold_floor``).
    """

    gap_floor: float
    engage_decel: float
    hold_floor: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.gap_floor < math.inf:
            raise ValueError(
                f"gap_floor must be finite and >= 0 [m]; got {self.gap_floor}"
            )
        if not 0.0 < self.engage_decel < math.inf:
            raise ValueError(
                f"engage_decel must be finite and > 0 [m/s^2]; got {self.engage_decel}"
            )

    def limit(
        self,
        accel: Tensor,
        range_ahead: Tensor,
        rate_ahead: Tensor,
        hit_ahead: Tensor,
        length: Tensor,
    ) -> Tensor:
        """The acceleration with the emergency brake applied.

        Parameters
        ----------
        accel : Tensor of shape (B, C)
            The network's acceleration [m/s^2] of the driven vehicles.
        range_ahead, rate_ahead : Tensor of shape (B, C)
            Their front beam's range [m] (from the vehicle's centre) and
            range-rate [m/s] (negative while closing).
        hit_ahead : Tensor of int64, shape (B, C)
            Index of the vehicle the beam hits, ``-1`` for none.
        length : Tensor of shape (B, C)
            The driven vehicles' lengths [m].

        Returns
        -------
        Tensor of shape (B, C)
            ``min(accel, -d)`` where a vehicle is hit and ``d >
            engage_decel`` (or, with ``hold_floor``, the gap is inside the
            floor and closing); ``accel`` itself elsewhere.
        """
        gap = range_ahead - 0.5 * length
        closing = torch.clamp_min(-rate_ahead, 0.0)
        needed = self.needed_decel(gap, closing)
        engaged = (hit_ahead >= 0) & self.acts(gap, closing, needed)
        return torch.where(engaged, torch.minimum(accel, -needed), accel)

    def needed_decel(self, gap: Tensor, closing: Tensor) -> Tensor:
        """The constant deceleration that ends the closing ``gap_floor`` short [m/s^2].

        Parameters
        ----------
        gap : Tensor
            Bumper gap to the vehicle ahead [m].
        closing : Tensor
            Closing speed, ``>= 0`` [m/s]; the same shape.

        Returns
        -------
        Tensor
            ``closing^2 / (2 max(gap - gap_floor, 0.1 m))``.
        """
        room = torch.clamp_min(gap - self.gap_floor, _MIN_ROOM)
        return closing * closing / (2.0 * room)

    def acts(
        self, gap: Tensor, closing: Tensor, needed: Tensor | None = None
    ) -> Tensor:
        """Where the brake acts on a vehicle ahead at ``gap`` closing at ``closing``.

        Parameters
        ----------
        gap, closing : Tensor
            As :meth:`needed_decel`'s.
        needed : Tensor, optional
            :meth:`needed_decel` of them, if already computed.

        Returns
        -------
        Tensor of bool
            The needed deceleration exceeds ``engage_decel`` or, with
            ``hold_floor``, the gap is inside the floor and closing.
        """
        if needed is None:
            needed = self.needed_decel(gap, closing)
        acts = needed > self.engage_decel
        if self.hold_floor:
            acts = acts | ((gap < self.gap_floor) & (closing > 0.0))
        return acts

    def to_dict(self) -> dict[str, float | bool]:
        """The settings as JSON values (see :meth:`from_dict`).

        ``hold_floor`` is written only when true, so that a guard without it
        writes the same metadata as before the setting existed.
        """
        out: dict[str, float | bool] = {
            "gap_floor": self.gap_floor,
            "engage_decel": self.engage_decel,
        }
        if self.hold_floor:
            out["hold_floor"] = True
        return out

    @classmethod
    def from_dict(cls, data: object) -> BrakeGuard:
        """A guard from :meth:`to_dict`'s mapping, checked (untrusted input).

        Raises
        ------
        ValueError
            If ``data`` is not a mapping of the two numeric settings (finite,
            in range) and, optionally, ``hold_floor`` (a boolean), and nothing
            else.
        """
        keys, optional = {"gap_floor", "engage_decel"}, {"hold_floor"}
        if not isinstance(data, dict) or not keys <= set(data) <= keys | optional:
            raise ValueError(
                f"a brake guard is a mapping of {sorted(keys)} and optionally "
                f"'hold_floor'; got {data!r}"
            )
        values = [data["gap_floor"], data["engage_decel"]]
        if not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in values
        ):
            raise ValueError(f"a brake guard's settings are numbers; got {data!r}")
        hold = data.get("hold_floor", False)
        if not isinstance(hold, bool):
            raise ValueError(f"a brake guard's hold_floor is a boolean; got {data!r}")
        return cls(float(values[0]), float(values[1]), hold)

    @classmethod
    def parse(cls, text: str) -> BrakeGuard:
        """``"GAP_FLOOR,ENGAGE_DECEL[,hold]"`` (e.g. ``"2,1"``, ``"2,2,hold"``).

        A third item ``hold`` sets ``hold_floor``.

        Raises
        ------
        ValueError
            If ``text`` is not two numbers separated by a comma (and
            optionally ``hold``), or they are out of range.
        """
        parts = [p.strip() for p in text.split(",")]
        hold = len(parts) == 3 and parts[2].lower() == "hold"
        numbers = parts[:2] if hold else parts
        try:
            floor, decel = (float(p) for p in numbers)
        except ValueError:
            raise ValueError(
                f"a brake guard is GAP_FLOOR,ENGAGE_DECEL in m and m/s^2, "
                f"optionally followed by ',hold', e.g. 2,1 or 2,2,hold; got {text!r}"
            ) from None
        return cls(floor, decel, hold)

    def text(self) -> str:
        """The settings as :meth:`parse` reads them, e.g. ``"2,2,hold"``."""
        hold = ",hold" if self.hold_floor else ""
        return f"{self.gap_floor:g},{self.engage_decel:g}{hold}"


def parse_guard(text: str) -> BrakeGuard | None:
    """A command line's brake: ``"none"`` or ``"GAP_FLOOR,ENGAGE_DECEL[,hold]"``.

    Raises
    ------
    ValueError
        As :meth:`BrakeGuard.parse`.
    """
    if text.strip().lower() == "none":
        return None
    return BrakeGuard.parse(text)
