"""The settings of subset simulation (:mod:`avrisk.rare.splitting`).

What one run of the levels is set by, validated (:class:`SplittingSettings`),
and the bounds on its calls of ``f`` that follow from them: one replicate's
levels, the run with every regrowth its settings allow, and the cap on them
(*Replicates* and *Regrowth* in :mod:`avrisk.rare.splitting_replicates`).
"""

from __future__ import annotations

from typing import Self

from pydantic import Field, ValidationInfo, field_validator, model_validator

from avrisk.rare.estimator import EstimatorSettings

__all__ = ["SplittingSettings"]


class SplittingSettings(EstimatorSettings):
    """Settings of subset simulation (module docstring).

    Attributes
    ----------
    n_particles : int, default=2000
        Particles per level ``N``.
    p0 : float, default=0.1
        Quantile of ``f`` that sets each next level (share of survivors).
    p0_max : float, default=0.5
        Largest share of survivors ties of ``f`` may leave at a level before
        the level moves below the tied value (at least ``p0``).
    max_levels : int, default=12
        Most particle sets, the draws of ``P0`` included; a run that does not
        reach ``gamma`` within them is regrown (``regrow``), and with none
        left the answer leans on the others, or on the first draws alone.
    n_moves : int, default=1
        pCN proposals per kept chain state (``> 1`` thins the chains).
    initial_beta : float, default=0.6
        pCN step of the first moves, in (0, 1]; then adapted.
    min_survivors : int, default=10
        Fewest of the first ``N`` draws of ``P0`` that must lie below a tie of
        ``f`` at their level (a plateau, e.g. a capped TTC); fewer, and the
        first set grows to ``plateau_draws N`` draws (*Plateaus* in
        :mod:`avrisk.rare.splitting_levels`).
    plateau_draws : int, default=8
        Draws of a first set grown on a plateau, in multiples of ``N`` (1:
        never grown).
    replicates : int, default=2
        Independent replicates of the levels, ``n_particles / replicates``
        particles each (*Replicates* in
        :mod:`avrisk.rare.splitting_replicates`).
    regrow : int, default=2
        Times a replicate whose ``max_levels`` sets end above ``gamma`` runs
        again, fresh, with twice its particles (*Regrowth* there): how far the
        run may adapt its calls to an event whose levels are harder to follow
        than the settings planned for.
    correlated_moves : int, default=1
        Times ``n_moves`` the chains of a level move when the set their seeds
        come from was made by chains whose states are correlated, inflating
        the variance of its share of survivors more than ``CORRELATED`` times
        (*Moves* in :mod:`avrisk.rare.splitting_moves`): how far the run may
        adapt its calls to chains that mix slowly. 1: never (subset
        simulation's own default: its one move per state leaves chains that
        correlated at every level; ``splitting_is`` takes 2). Taken only where
        the run's bound with every level so moved stays within ``max_calls``.
    max_calls : int or None, default=None
        The most calls of ``f`` the run may make, regrowths included: a
        replicate is regrown only while the most the rest of the run can take
        stays within it. None: every regrowth ``regrow`` allows (the
        estimator's ``budget()`` is then the bound).
    """

    OMIT_IF_DEFAULT = (
        "min_survivors",
        "plateau_draws",
        "correlated_moves",
        "max_calls",
    )

    n_particles: int = Field(2000, ge=10, description="Particles per level N.")
    p0: float = Field(
        0.1, gt=0.0, lt=1.0, description="Quantile of f that sets the next level."
    )
    p0_max: float = Field(
        0.5,
        gt=0.0,
        lt=1.0,
        description="Largest share of survivors that ties may leave at a level.",
    )
    max_levels: int = Field(
        12, ge=1, description="Most particle sets (P0 draws included)."
    )
    n_moves: int = Field(
        1, ge=1, description="pCN proposals per kept chain state (thinning)."
    )
    initial_beta: float = Field(
        0.6, gt=0.0, le=1.0, description="pCN step of the first level's moves."
    )
    min_survivors: int = Field(
        10, ge=1, description="Fewest draws of P0 below a plateau of f before more."
    )
    plateau_draws: int = Field(
        8, ge=1, description="Draws of a first set grown on a plateau, times N."
    )
    replicates: int = Field(
        2, ge=1, description="Independent replicates of the levels (N split)."
    )
    regrow: int = Field(
        2,
        ge=0,
        description="Times a replicate that ran out of levels runs again with "
        "twice its particles.",
    )
    correlated_moves: int = Field(
        1,
        ge=1,
        description="Times n_moves a level's chains move after a set of correlated "
        "chains (1: never).",
    )
    max_calls: int | None = Field(
        None,
        ge=1,
        description="The most calls of f, regrowths included (None: as regrow allows).",
    )

    @field_validator("p0_max")
    @classmethod
    def _at_least_p0(cls, p0_max: float, info: ValidationInfo) -> float:
        p0 = info.data.get("p0")
        if p0 is not None and p0_max < p0:
            raise ValueError(f"p0_max ({p0_max}) must be at least p0 ({p0})")
        return p0_max

    @field_validator("replicates")
    @classmethod
    def _particles_each(cls, replicates: int, info: ValidationInfo) -> int:
        n = info.data.get("n_particles")
        if n is not None and n // replicates < 10:
            raise ValueError(
                f"{replicates} replicates of n_particles={n} leave fewer than 10 "
                "particles each"
            )
        return replicates

    @model_validator(mode="after")
    def _cap_holds_the_plan(self) -> Self:
        if self.max_calls is not None and self.max_calls < self.bound(regrow=0):
            raise ValueError(
                f"max_calls={self.max_calls:,} is less than the run's bound without "
                f"regrowth ({self.bound(regrow=0):,} calls)"
            )
        return self

    def levels_bound(self, n: int, correlated: bool = False) -> int:
        """The most calls of one replicate's levels with ``n`` particles per level.

        ``n`` draws (``plateau_draws n`` on a plateau), then at most ``n
        n_moves`` proposals per further set (``correlated``: times
        ``correlated_moves``, every set moved as after correlated chains).
        """
        moves = self.n_moves * (self.correlated_moves if correlated else 1)
        return n * self.plateau_draws + n * (self.max_levels - 1) * moves

    def tail_bound(self, n: int, correlated: bool = False) -> int:
        """The most calls after the levels, given ``n`` particles at ``gamma``: none."""
        return 0

    def bound(self, regrow: int, correlated: bool = False) -> int:
        """The most calls of a run whose replicates are each regrown ``regrow`` times.

        The replicates share the ``N`` particles of a level, so they change no
        bound; each regrown ``regrow`` times runs ``2^(regrow + 1) - 1`` times
        its levels' bound and ends with ``2^regrow`` times its particles at
        ``gamma``. ``correlated``: every set moved ``correlated_moves`` times
        more.
        """
        levels = self.levels_bound(self.n_particles, correlated)
        levels *= 2 ** (regrow + 1) - 1
        return levels + self.tail_bound(self.n_particles * 2**regrow, correlated)

    def moves_adapt(self) -> bool:
        """Whether levels after correlated chains move more (``correlated_moves``).

        Only where the run's bound without regrowth, every set so moved, stays
        within ``max_calls``: a cap the plan already fills leaves no room.
        """
        return self.correlated_moves > 1 and (
            self.max_calls is None or self.bound(0, correlated=True) <= self.max_calls
        )

    def correlated_factor(self) -> int:
        """``correlated_moves`` where :meth:`moves_adapt` allows it, else 1."""
        return self.correlated_moves if self.moves_adapt() else 1

    def one_replicate(self, n_particles: int) -> SplittingSettings:
        """The settings of one replicate's levels, with ``n_particles`` per level."""
        return self.model_copy(
            update={
                "n_particles": n_particles,
                "replicates": 1,
                "regrow": 0,
                # decided for the whole run, whose bound the cap is on
                "correlated_moves": self.correlated_factor(),
            }
        )
