"""Subset simulation (adaptive multilevel splitting) with pCN moves in normal space.

Au & Beck (2001) write ``p = P0(f <= gamma)`` as a product of conditional
probabilities of nested levels ``inf = b_0 > b_1 > ... > b_{L-1} > b_L = gamma``:

    p = prod_{l=1}^{L} P0(f <= b_l | f <= b_{l-1})

and estimate each factor from ``N`` particles of ``P0`` conditioned on ``f <=
b_{l-1}``. Particle set 0 is ``N`` draws of ``P0``. From set ``l`` the next
level ``b_{l+1}`` is the ``p0``-quantile of its ``f`` (see *Ties*), or
``gamma`` once that quantile is at or below ``gamma`` (set ``l`` is then the
last). Its ``n_l`` particles with ``f <= b_{l+1}`` (the survivors) seed
``n_l`` Markov chains, of ``N // n_l`` states or one more, seed included: their
``N`` states are set ``l + 1``. With exact counts, not ``p0`` assumed,

    p_hat = prod_{l=0}^{L-2} (n_l / N_l) * (#{f <= gamma in set L-1} / N_{L-1}),

``N_l = N`` but for a first set grown on a plateau (*Plateaus*), whose factor
counts its further draws only.

A test threshold ``g`` is estimated from the deepest set conditioned on a level
at or above ``g``; below ``gamma`` it may see no particle (``p = 0``; its
interval then reaches up to that of ``gamma``).

The levels run ``replicates`` times, independently, with ``N / replicates``
particles each; the answer is their mean, and replicates that disagree beyond
their errors, or that ran out of levels, make the run say caution. One that
ran out runs again with twice its particles (*Replicates* and *Regrowth* in
:mod:`avrisk.rare.splitting_replicates`).

The method is six modules: this one, the estimator; its settings and their
bounds on the calls of ``f`` (:mod:`avrisk.rare.splitting_settings`);
:mod:`avrisk.rare.splitting_levels`, the particle sets, the choice of each
level and the estimate with its error (its sections *Ties*, *Plateaus* and
*Standard error*, which the sections named here refer to), that error's
family tree (:mod:`avrisk.rare.splitting_genealogy`); the draws of ``P0``
and the pCN chains that make the sets (:mod:`avrisk.rare.splitting_moves`:
*Moves*, *Seeds and resume*); what the replicates share
(:mod:`avrisk.rare.splitting_replicates`).

Failed samples
--------------
A sample whose evaluation failed (``status != 0``) counts as outside every
level (its ``f`` as ``+inf``): a failed proposal is rejected. They are counted
(``details["n_failed"]``, with a warning) but not bracketed as in naive Monte
Carlo and cross-entropy: counted dangerous, they would change the levels and
the chains themselves, so no second estimate follows from the same samples.

References
----------
S.-K. Au, J. L. Beck. "Estimation of small failure probabilities in high
dimensions by subset simulation." Probabilistic Engineering Mechanics 16, 2001.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from avrisk.rare.black_box import estimate
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    DiagnosticTable,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily
from avrisk.rare.problem import BatchFunction, RareEventProblem
from avrisk.rare.results import Estimate, SearchConvergence
from avrisk.rare.splitting_levels import (
    ParticleSet,
    SplittingState,
    level_cov_squared,
    levels_estimate,
    next_level,
    on_plateau,
)
from avrisk.rare.splitting_moves import draw_p0, drawn_more, move_chains, moves_after
from avrisk.rare.splitting_replicates import (
    ReplicatesState,
    combined_levels,
    disagreement_doubts,
    exhausted_doubts,
    few_survivors,
    first_draws_estimate,
    regrown_doubts,
    regrowth_fits,
    replicates_record,
)
from avrisk.rare.splitting_settings import SplittingSettings

#: The levels' diagnostics in plain words (:meth:`SubsetSimulation.diagnostics`).
LEVELS_NOTE = (
    "Set 0 is samples drawn from P0. Its level is the f below which the share "
    "p0 of them lies (the survivors); the next set grows from the survivors by "
    "small random moves that stay below that level, and so on, each level "
    "lower, until the level reaches gamma. p is the product of the shares of "
    "survivors. Independent replicates each run their own levels."
)


class SplittingInfo(NamedTuple):
    """Diagnostics of one level (one particle set).

    Attributes
    ----------
    index : int
        Index of the set (0: draws of ``P0``).
    level : float
        Level chosen from this set's ``f`` (``gamma`` on the last set).
    n_survivors : int
        Particles of the set with ``f <= level``.
    n_chains : int
        Chains that made the set (``N`` independent draws for set 0).
    acceptance : float
        Share of the set's pCN proposals accepted (NaN for set 0).
    beta : float
        pCN step after the set's moves.
    cov : float
        Coefficient of variation of the set's factor ``n_survivors / N``
        (Au & Beck, with the chains' correlation).
    n_failed : int
        Evaluations of this set that failed.
    n_evals : int
        Calls of ``f`` so far, this set included.
    last_stage : int
        The last stage (evaluated batch) of this set: its samples are those of
        the stages after the previous set's ``last_stage`` up to this one (a
        samples-table row's ``stage`` names its set, :meth:`stage_label`).
    replicate : int, default=0
        Independent replicate of the levels the set belongs to (several in
        :mod:`avrisk.rare.splitting_importance`).
    moves : int, default=0
        pCN proposals per kept state that made the set (0 for draws of
        ``P0``; more than ``n_moves`` after correlated chains,
        :func:`~avrisk.rare.splitting_moves.moves_after`).
    """

    index: int
    level: float
    n_survivors: int
    n_chains: int
    acceptance: float
    beta: float
    cov: float
    n_failed: int
    n_evals: int
    last_stage: int
    replicate: int = 0
    moves: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN becomes ``None``)."""
        return {
            k: None if isinstance(v, float) and math.isnan(v) else v
            for k, v in self._asdict().items()
        }


class OneReplicate:
    """One replicate's levels, set by set: what :class:`SubsetSimulation` repeats.

    Its ``settings`` are the run's with the replicate's particles per level
    (:meth:`SplittingSettings.one_replicate`).
    """

    def __init__(self, settings: SplittingSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """The most calls of its levels (:meth:`SplittingSettings.levels_bound`)."""
        return self.settings.levels_bound(self.settings.n_particles)

    def init(self, problem: RareEventProblem) -> SplittingState:
        """No particles yet; ``beta`` at its initial value."""
        empty = np.empty((0, problem.base.dim))
        return SplittingState(empty, (), self.settings.initial_beta, False, 0, 0, 0, 0)

    def done(self, state: SplittingState) -> bool:
        """Once a set's level is ``gamma``, or ``max_levels`` sets did not reach it."""
        return state.reached or state.exhausted

    def step(
        self,
        state: SplittingState,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> tuple[SplittingState, SplittingInfo]:
        """The next particle set (``P0`` draws, then chains) and its level.

        Raises
        ------
        SplittingError
            If the chains stop moving.
        """
        s = self.settings
        current = state.sets[-1].level if state.sets else math.inf
        counted_from = moves = 0
        if state.sets:
            moves = moves_after(state.sets[-1], s.n_moves, s.correlated_moves)
            moved = move_chains(state, problem, context, moves, s.n_particles)
        else:
            moved = draw_p0(state, problem, context, s.n_particles)
            if s.plateau_draws > 1 and on_plateau(
                moved.values, problem.gamma, s.p0, s.p0_max, s.min_survivors
            ):
                counted_from = s.n_particles
                more = (s.plateau_draws - 1) * s.n_particles
                moved = drawn_more(moved, problem, context, more)
        flat = moved.values[~np.isnan(moved.values)]
        level = next_level(flat, current, problem.gamma, s.p0, s.p0_max)
        if level is None or (
            level > problem.gamma and np.count_nonzero(flat <= level) == flat.size
        ):
            level = problem.gamma  # nothing below a tie: a bound (*Plateaus*)
        sets = (*state.sets, ParticleSet(moved.values, level, counted_from))
        reached = level == problem.gamma
        n_evals = state.n_evals + moved.n_calls
        new_state = SplittingState(
            moved.z,
            sets,
            moved.beta,
            reached,
            moved.n_stages,
            n_evals,
            state.n_failed + moved.n_failed,
            moved.rounds_without_move,
            exhausted=not reached and len(sets) == s.max_levels,
        )
        info = SplittingInfo(
            index=len(state.sets),
            level=level,
            n_survivors=int(np.count_nonzero(flat <= level)),
            n_chains=moved.values.shape[0],
            acceptance=moved.acceptance,
            beta=moved.beta,
            cov=math.sqrt(level_cov_squared(sets[-1].counted, level)),
            n_failed=moved.n_failed,
            n_evals=n_evals,
            last_stage=moved.n_stages,
            moves=moves,
        )
        return new_state, info


@register_estimator
class SubsetSimulation:
    """Subset simulation (module docstring) as an Estimator, in replicates."""

    name = "splitting"
    label = "subset simulation"
    Settings: type[SplittingSettings] = SplittingSettings
    weighted = False
    budget_is_bound = True  # its levels may reach gamma before max_levels
    searches = True

    def __init__(self, settings: SplittingSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """An upper bound for the progress bar: every replicate regrown to the end.

        :meth:`SplittingSettings.bound`, or ``max_calls`` where it is lower; a
        run that reaches ``gamma`` sooner, as most do, makes fewer calls.
        """
        s = self.settings
        bound = s.bound(s.regrow, correlated=s.moves_adapt())
        return bound if s.max_calls is None else min(bound, s.max_calls)

    def planned_budget(self) -> int:
        """The bound of a run none of whose replicates is regrown.

        What the plan and the progress bar show; :meth:`budget` adds every
        regrowth the settings allow.
        """
        return min(self.settings.bound(regrow=0), self.budget())

    def budget_not_redrawn(self) -> int:
        """All of :meth:`budget`: its points are drawn in standard space and moved."""
        return self.budget()

    def describe(self) -> str:
        """``"subset simulation, 2,000 particles per level, p0 0.1, regrown ..."``."""
        s = self.settings
        text = f"subset simulation, {s.n_particles:,} particles per level, p0 {s.p0:g}"
        text += f", {s.n_moves} moves per state" if s.n_moves > 1 else ""
        return text + (f", regrown up to {s.regrow}x" if s.regrow else "")

    def levels(self, n_particles: int) -> OneReplicate:
        """One replicate's levels, with ``n_particles`` per level."""
        return OneReplicate(self.settings.one_replicate(n_particles))

    def init(self, problem: RareEventProblem) -> ReplicatesState:
        """The first replicate's levels, not yet begun: ``n_particles / replicates``."""
        n = self.settings.n_particles // self.settings.replicates
        return ReplicatesState((), self.levels(n).init(problem), (n,))

    def done(self, state: ReplicatesState) -> bool:
        """Once the last replicate's levels are over, and it is not to be regrown."""
        return (
            self.levels(state.sizes[-1]).done(state.current)
            and not self._regrows(state)
            and state.filled + 1 == self.settings.replicates
        )

    def _regrows(self, state: ReplicatesState) -> bool:
        """Whether the replicate that just ended out of levels runs again, larger."""
        s = self.settings
        regrown = round(math.log2(state.sizes[-1] / state.sizes[0]))
        if not state.current.exhausted or regrown >= s.regrow:
            return False
        correlated = s.moves_adapt()
        return regrowth_fits(
            state,
            s.replicates,
            functools.partial(s.levels_bound, correlated=correlated),
            functools.partial(s.tail_bound, correlated=correlated),
            self.budget(),
        )

    def step(
        self,
        state: ReplicatesState,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> tuple[ReplicatesState, SplittingInfo]:
        """The next set of the replicate under way, or the first of the next.

        A replicate's stages follow the last one's, so that every stage has
        its own random numbers and a resumed run replays them in order.
        """
        if self.levels(state.sizes[-1]).done(state.current):
            regrown = self._regrows(state)
            n = 2 * state.sizes[-1] if regrown else state.sizes[0]
            fresh = (
                self.levels(n)
                .init(problem)
                ._replace(
                    n_stages=state.current.n_stages, n_evals=state.current.n_evals
                )
            )
            state = ReplicatesState(
                state.all, fresh, (*state.sizes, n), state.filled + (not regrown)
            )
        current, info = self.levels(state.sizes[-1]).step(
            state.current, problem, context
        )
        return (
            state._replace(current=current),
            info._replace(replicate=len(state.finished)),
        )

    def finalize(
        self,
        state: ReplicatesState,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> Estimate:
        """The replicates' mean product and its error, for every threshold.

        Each replicate that reached ``gamma`` estimates ``p`` by its product;
        the answer is their mean
        (:func:`~avrisk.rare.splitting_replicates.combined_levels`). With
        none, naive sampling's of their first draws
        (:func:`~avrisk.rare.splitting_replicates.first_draws_estimate`).
        """
        n_failed = sum(r.n_failed for r in state.all)
        if n_failed:
            warnings.warn(
                f"{n_failed} evaluations of f failed; subset simulation counts "
                "them outside every level (a failed proposal is rejected), with no "
                "bracket: fix what makes f fail (see the 'status' column)",
                UserWarning,
                stacklevel=2,
            )
        reached, n = state.reached(), self.settings.replicates
        if not reached:  # a bound, most often: labelled caution (exhausted_doubts)
            bound = first_draws_estimate(state, problem, state.sizes[-1])
            return dataclasses.replace(
                bound, details=bound.details | replicates_record(state, [], n)
            )
        own = [levels_estimate(r, problem, m, genealogy=True) for r, m in reached]
        combined = combined_levels(own, problem, sum(m for _, m in reached))
        record = replicates_record(state, own, n)
        return dataclasses.replace(combined, details=combined.details | record)

    def progress(self, info: SplittingInfo) -> str:
        """``"replicate 2/2, set 3: f <= 1.23, 212 survivors, accepted 31%, ..."``."""
        moves = (
            "independent draws"
            if math.isnan(info.acceptance)
            else f"accepted {info.acceptance:.0%}, beta {info.beta:.2g}"
        )
        text = (
            f"set {info.index}: f <= {info.level:.3g}, "
            f"{info.n_survivors} survivors, {moves}"
        )
        r, i = self.settings.replicates, info.replicate
        if r == 1 and not i:
            return text
        return f"replicate {i + 1}{f'/{r}' if i < r else ' (regrown)'}, {text}"

    def checkpoint(
        self, state: ReplicatesState, infos: Sequence[SplittingInfo]
    ) -> dict[str, Any]:
        """The levels so far, every replicate's (for inspection and reports)."""
        return {
            "replicates_done": len(state.finished),
            "levels_done": sum(len(r.sets) for r in state.all),
            "n_evals": state.current.n_evals,
            "beta": state.current.beta,
            "levels": [i.to_dict() for i in infos],
        }

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """Levels of ``f``, survivors, moves per state, acceptance and ``beta`` per set.

        One table per independent replicate of the levels (each numbers its
        sets from 0), titled with its number when there are several.
        """
        history = estimate.get("history") or []
        columns = ("set", "level", "survivors", "moves", "acceptance", "beta")
        keys = ("index", "level", "n_survivors", "moves", "acceptance", "beta")
        replicates = sorted({h.get("replicate", 0) for h in history})
        return [
            DiagnosticTable(
                "Subset simulation levels"
                + (f", replicate {r + 1}" if len(replicates) > 1 else ""),
                columns,
                [
                    tuple(h.get(k) for k in keys)  # no moves: a run before them
                    for h in history
                    if h.get("replicate", 0) == r
                ],
                lines=("level",),
                bars="survivors",
                note=LEVELS_NOTE,
            )
            for r in replicates
        ]

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """``"set 3"``, or ``"replicate 2, set 3"``: the set that drew ``stage``.

        ``"the levels"`` where the summary does not say (one written before the
        sets recorded their last stage).
        """
        history = estimate.get("history") or []
        found = next((h for h in history if stage <= h.get("last_stage", -1)), None)
        if found is None:
            return "the levels"
        several = any(h.get("replicate", 0) for h in history)
        where = f"replicate {found['replicate'] + 1}, " if several else ""
        return f"{where}set {found['index']}"

    @staticmethod
    def convergence(estimate: dict[str, Any], gamma: float) -> SearchConvergence | None:
        """None: its levels end at ``gamma``, or the run fails (SplittingError)."""
        return None

    @staticmethod
    def doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
        """Too few particles under a level; replicates that disagree.

        A level held by fewer than ``MIN_RELIABLE_ESS`` particles (a plateau):
        the interval rests on too few draws. Hits that descend from one or two
        families of a set are no doubt of their own: the family tree's
        interval takes Student's t at their number less one (at least 1),
        wide enough to say it (:mod:`avrisk.rare.splitting_genealogy`).
        Replicates that differ beyond their errors followed different regions
        or mechanisms: their mean is of products that each miss part of the
        event. One that ran out of levels leaves the answer to the others; one
        regrown after it leans high.
        """
        details = estimate.get("details") or {}
        reasons = list(few_survivors(details.get("survivors") or []))
        if gamma == estimate.get("gamma"):
            reasons.extend(
                disagreement_doubts(details)
                + exhausted_doubts(details)
                + regrown_doubts(details)
            )
        return tuple(reasons)


def subset_simulation(
    f: BatchFunction, base: ExponentialFamily, gamma: float, **options: Any
) -> Estimate:
    """Subset simulation: ``estimate("splitting", f, base, gamma, **options)``."""
    return estimate("splitting", f, base, gamma, **options)
