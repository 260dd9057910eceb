"""The emergency brake's settings fitted to human closing-in on training windows.

A :class:`~avrisk.agents.drivers.guard.BrakeGuard` acts where stopping the
closing ``gap_floor`` short of the vehicle ahead needs more than
``engage_decel`` (and, with ``hold_floor``, wherever the follower closes in
inside the floor). :func:`fit_brake_guard` sets both from what the human
followers of *training* windows do while they close in on their leader
(closing speed ``c = v_f - v_l > 0``), by one stated criterion, the brake as
the edge of the humans' envelope:

* ``gap_floor``: the humans' :data:`GAP_QUANTILE` quantile of the bumper gap
  over their closing steps: humans close in nearer than this in 1 of 100
  closing steps;
* ``engage_decel``: the :data:`DECEL_QUANTILE` quantile, over the same steps,
  of the constant deceleration ``c^2 / (2 max(g - gap_floor, 0.1 m))`` that
  would end their closing at that floor: the brake acts only where the
  closing is harder to stop than in 999 of 1,000 human closing steps;
* ``hold_floor`` true: the floor holds (no human follower of the data ran
  into its leader).

The realism scores play no part in it. :func:`guard_conditions` evaluates a
brake's condition on recorded or replayed followers (the brake's own
arithmetic, :meth:`BrakeGuard.acts`), so that how often it would act on the
humans and how often it acts on the models are counted alike.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from avrisk.agents.drivers.guard import BrakeGuard
from avrisk.learning.replay import CarFollowingWindows

__all__ = [
    "DECEL_QUANTILE",
    "GAP_QUANTILE",
    "GuardFit",
    "engagements",
    "fit_brake_guard",
    "guard_conditions",
]

#: Quantile of the humans' closing gaps that sets the floor.
GAP_QUANTILE = 0.01
#: Quantile of the humans' needed deceleration that sets the engagement.
DECEL_QUANTILE = 0.999


@dataclass(frozen=True)
class GuardFit:
    """A fitted brake and what it was fitted on.

    Attributes
    ----------
    guard : BrakeGuard
    closing_steps : int
        Human steps with a positive closing speed it was fitted on.
    windows : int
        Training windows they come from.
    gap_quantile, decel_quantile : float
        The criterion's quantile levels.
    human_share : float
        Share of the humans' steps (all, not only closing) in which the fitted
        brake's condition holds, in those same windows.
    """

    guard: BrakeGuard
    closing_steps: int
    windows: int
    gap_quantile: float
    decel_quantile: float
    human_share: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (the guard as :meth:`BrakeGuard.to_dict`)."""
        return asdict(self) | {"guard": self.guard.to_dict()}


def guard_conditions(
    guard: BrakeGuard,
    gap: NDArray[np.float64],
    v_f: NDArray[np.float64],
    v_l: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Where ``guard`` would act on followers at these states.

    The leader is taken to be on the follower's front beam; the condition is
    the brake's own (:meth:`BrakeGuard.acts`), whatever the follower's
    acceleration.

    Parameters
    ----------
    guard : BrakeGuard
    gap, v_f, v_l : ndarray of shape (W, T+1)
        Bumper gap [m], follower and leader speed [m/s].

    Returns
    -------
    ndarray of bool, shape (W, T+1)
    """
    g = torch.as_tensor(gap, dtype=torch.float64)
    closing = torch.clamp_min(torch.as_tensor(v_f - v_l, dtype=torch.float64), 0.0)
    return guard.acts(g, closing).numpy()


def engagements(acting: NDArray[np.bool_], alive: NDArray[np.bool_]) -> int:
    """Episodes of the brake acting: alive steps where it acts and did not before.

    Parameters
    ----------
    acting, alive : ndarray of bool, shape (W, T+1)

    Returns
    -------
    int
        Onsets, a window's first step counting as one if the brake acts there.
    """
    on = acting & alive
    before = np.zeros_like(on)
    before[:, 1:] = on[:, :-1]
    return int(np.count_nonzero(on & ~before))


def fit_brake_guard(
    windows: CarFollowingWindows,
    gap_quantile: float = GAP_QUANTILE,
    decel_quantile: float = DECEL_QUANTILE,
) -> GuardFit:
    """Fit the brake to the human followers of ``windows`` (module docstring).

    Parameters
    ----------
    windows : CarFollowingWindows
        Training windows (their recorded followers).
    gap_quantile, decel_quantile : float
        In (0, 1).

    Returns
    -------
    GuardFit

    Raises
    ------
    ValueError
        For quantiles outside (0, 1) or windows in which no human closes in.
    """
    if not (0.0 < gap_quantile < 1.0 and 0.0 < decel_quantile < 1.0):
        raise ValueError(
            f"quantiles must be in (0, 1); got {gap_quantile} and {decel_quantile}"
        )
    closing = windows.v_f - windows.v_l
    steps = closing > 0
    if not steps.any():
        raise ValueError("no human follower closes in on its leader in these windows")
    floor = max(float(np.quantile(windows.gap[steps], gap_quantile)), 0.0)
    needed = BrakeGuard(floor, 1.0).needed_decel(
        torch.as_tensor(windows.gap[steps]), torch.as_tensor(closing[steps])
    )
    decel = float(np.quantile(needed.numpy(), decel_quantile))
    guard = BrakeGuard(floor, decel, hold_floor=True)
    share = guard_conditions(guard, windows.gap, windows.v_f, windows.v_l).mean()
    return GuardFit(
        guard=guard,
        closing_steps=int(steps.sum()),
        windows=len(windows),
        gap_quantile=gap_quantile,
        decel_quantile=decel_quantile,
        human_share=float(share),
    )
