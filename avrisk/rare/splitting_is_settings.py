"""The settings of ``splitting_is`` (:mod:`avrisk.rare.splitting_importance`).

Those of subset simulation's levels (:mod:`avrisk.rare.splitting_settings`),
with the moves at ``gamma``, the fit and the importance-sampling stage, and
the bound on their calls of ``f``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from avrisk.rare.cross_entropy import ShareOfP0
from avrisk.rare.splitting_settings import SplittingSettings

__all__ = ["SplittingISSettings"]


class SplittingISSettings(SplittingSettings):
    """Settings of subset simulation followed by importance sampling.

    Those of :class:`~avrisk.rare.splitting.SplittingSettings` (the levels),
    and of the importance-sampling stage:

    Attributes
    ----------
    n_moves : int, default=2
        pCN proposals per kept chain state at every level (one for subset
        simulation alone): the proposal is fitted to the particles, so their
        spread over each level's conditional law matters here as well as their
        level; with one move per state a chain's kept states sit closer to its
        seed.
    correlated_moves : int, default=2
        As in :class:`~avrisk.rare.splitting.SplittingSettings` (1 there):
        twice the moves at a level after chains correlated beyond
        ``CORRELATED`` (:func:`~avrisk.rare.splitting_moves.moves_after`).
    n_final : int, default=10000
        Samples of the fitted proposal.
    n_components : int, default=4
        Mean shifts seeded from the particles (fewer survive merging on one
        failure region).
    defensive : float, default=0.1
        Weight ``lam`` of ``P0`` in the proposal, in [0, 1): every weight is
        at most ``1 / lam``.
    min_weight : float, default=0.02
        Share of the particles below which a component dies in EM.
    shift : {"all", "searched"}, default="all"
        Which standard coordinates the shifts may move: all of them, or only
        those the base's cross-entropy box searches
        (:meth:`~avrisk.rare.families.base.ExponentialFamily.searched_coordinates`).
    fit_variances : bool, default=True
        Whether the proposal may also fit each shifted coordinate's variance
        (where the held-out likelihood clearly prefers it; step 3).
    moves_at_gamma : int or None, default=None
        pCN proposals per kept state in the moves at ``gamma`` (step 2), the
        particles the proposal is fitted to; None: ``n_moves``, as at every
        level. More spread those particles over the event's law where one
        move per state leaves them narrower than it, at ``N`` calls each.
    refresh_rounds : int, default=2
        Rounds of fresh draws of the coordinates the particles at ``gamma``
        do not inform, after the moves there (step 2;
        :func:`~avrisk.rare.splitting_moves.refreshed`), at one call per
        particle each: what their ancestors left in those coordinates is
        not fitted as a shift. 0: none. Runs recorded before it became the
        default (0 then) record no value, and resume with 0 given.
    more_replicates : bool, default=True
        Whether a levels' answer less precise than a factor of 2 at three
        standard errors takes more replicates of the levels, within the
        budget (:mod:`avrisk.rare.splitting_precision`). Runs recorded
        before it record no value, and resume with False given.
    """

    OMIT_IF_DEFAULT = (*SplittingSettings.OMIT_IF_DEFAULT, "moves_at_gamma")
    OMIT_AT_FORMER_DEFAULT = {"refresh_rounds": 0, "more_replicates": False}

    n_moves: int = Field(
        2, ge=1, description="pCN proposals per kept chain state (thinning)."
    )
    correlated_moves: int = Field(
        2,
        ge=1,
        description="Times n_moves a level's chains move after a set of correlated "
        "chains (1: never).",
    )
    n_final: int = Field(10_000, ge=1, description="Samples of the fitted proposal.")
    n_components: int = Field(
        4, ge=1, description="Mean shifts seeded from the particles."
    )
    defensive: ShareOfP0 = Field(
        0.1, description="Weight of P0 in the proposal (weights <= 1/defensive)."
    )
    min_weight: float = Field(
        0.02,
        gt=0.0,
        lt=1.0,
        description="Share of the particles below which a component dies.",
    )
    shift: Literal["all", "searched"] = Field(
        "all",
        description="Standard coordinates the shifts may move: 'all', or those the "
        "base's CE box searches ('searched').",
    )

    fit_variances: bool = Field(
        True,
        description="Whether the proposal may fit each shifted coordinate's "
        "variance too (where held-out particles clearly prefer it).",
    )

    moves_at_gamma: int | None = Field(
        None,
        ge=1,
        description="pCN proposals per kept state in the moves at gamma "
        "(None: n_moves).",
    )

    refresh_rounds: int = Field(
        2,
        ge=0,
        description="Rounds of fresh draws of the coordinates the particles at "
        "gamma do not inform (0: none).",
    )

    more_replicates: bool = Field(
        True,
        description="Whether an imprecise levels' answer takes more replicates "
        "of the levels, within the budget.",
    )

    def gamma_moves(self) -> int:
        """The pCN proposals per kept state in the moves at ``gamma``."""
        return self.n_moves if self.moves_at_gamma is None else self.moves_at_gamma

    def tail_bound(self, n: int, correlated: bool = False) -> int:
        """The moves at ``gamma`` on ``n`` particles, their refreshes, the final stage.

        ``correlated``: the moves at ``gamma`` taken ``correlated_moves`` times
        more, as after correlated chains.
        """
        moves = self.gamma_moves() * (self.correlated_moves if correlated else 1)
        return n * (moves + self.refresh_rounds) + self.n_final
