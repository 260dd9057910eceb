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

Moves
-----
Chains move in the space of independent standard normals of the base family
(:meth:`~avrisk.rare.families.base.ExponentialFamily.to_standard_normal`):
``X = T^-1(Z)`` with ``Z ~ N(0, I)``. A preconditioned Crank-Nicolson proposal
``z' = sqrt(1 - beta^2) z + beta eps``, ``eps ~ N(0, I)``, is reversible with
respect to ``N(0, I)``, so accepting it iff ``f(T^-1(z')) <= b_l`` leaves ``P0``
conditioned on ``f <= b_l`` invariant, with no density ratio; and its
acceptance does not fall with the dimension. The chains move in lockstep, one
round of proposals at a time; after each round ``beta`` is multiplied by
``exp(ADAPT_GAIN (accepted - TARGET_ACCEPTANCE proposed) / chains)`` (clipped
to ``[MIN_BETA, 1]``), which drives the acceptance rate towards
``TARGET_ACCEPTANCE = 0.3``; ``beta`` carries over from level to level. A chain
that is refused keeps its state (as Metropolis-Hastings does); only when no
chain accepts in ``MAX_ROUNDS_WITHOUT_MOVE`` rounds in a row with ``beta``
already at ``MIN_BETA`` (a step that barely moves: the set below the level has
no volume, or ``f`` jumps) does the run stop with a :class:`SplittingError`. With
``n_moves > 1`` a chain keeps every ``n_moves``-th state only (thinning). For a
seeded (stochastic) ``f`` each proposal has its own seed: the chain moves on
``(x, seed)``, and a fresh seed is an independence proposal from its prior, so
the move stays reversible.

Ties
----
Many rollouts may share one value of ``f`` (``inf`` for no encounter, ``0`` for
crashes, a capped or coarse ``f``). The level is still the quantile and the
survivors are counted exactly (``f <= level``). When ties leave more than
``p0_max`` of the particles at or below the quantile, the level moves to the
largest value below the tie: the factor is then the share strictly below it,
counted exactly as generalized splitting does, and the chains stay in ``f <=
level``, so the moves keep the conditional law invariant. The level must fall
at every set: one that cannot (the tie at the current level holds the whole
set) ends the levels with a bound (*Plateaus*).

Plateaus
--------
``f`` may be constant on most of ``P0`` (a TTC capped where nothing closes): a
first set of ``N`` draws may then hold few or no particles below the tie.
When it holds fewer than ``min_survivors`` below it (or every draw at it),
the first set takes ``(plateau_draws - 1) N`` more draws of ``P0``. Its factor
is the share of those further draws alone: the first ``N`` decided that they
were drawn, and a count that decides its own sample size is biased (stopping
at the ``m``-th hit overstates ``p`` by about ``m / (m - 1)``); all of the
set's particles below the level seed chains. With some below, the levels go
on (few chains: a wider interval, from their correlation). With none counted,
the answer is a bound, as naive Monte Carlo's with no hit: ``p`` is reported
as 0 with the interval ``[0, u]``, ``u`` the product of the factors so far
times the exact 95% upper bound of a share of 0 of the last set
(``details["bound_only"]``). The same holds for a later set whose particles
all tie at its level. No run stops on a flat ``f``: it is an event the draws
never came near, not a proof that it cannot happen.

Standard error
--------------
Au & Beck's coefficient of variation: level ``l`` contributes ``delta_l^2 =
(1 - p_l) / (N p_l) (1 + gamma_l)`` with ``gamma_l = 2 sum_k (pairs_k / N)
rho_l(k)``, ``rho_l(k)`` the correlation of the indicators ``1{f <= b_{l+1}}``
``k`` states apart in a chain, estimated over the ``pairs_k`` such pairs of
the level's chains (set 0 is independent: ``gamma_0 = 0``), and ``delta^2 =
sum_l delta_l^2``. The levels are taken as uncorrelated (Au & Beck's
approximation; their positive correlation makes it somewhat optimistic).
``stderr = p_hat delta``; the interval is normal on ``log p`` with ``Var(log
p_hat) = log(1 + delta^2)``: ``log p_hat`` is a sum over levels, so closer to
normal than the skewed product, and the interval stays above 0. Measured on
the 2-d linear problem at ``p = 1e-6`` (400 seeds): at ``N = 2000`` the spread
of ``log p_hat`` is 8% above the reported one and the 95% interval covers
``p`` in 92% of runs; at ``N = 500``, 20% and 90%. The estimator also has Au &
Beck's ``O(1/N)`` bias, upwards there: +2% (+-1.5%) at ``N = 2000``, +16%
(+-3%) at ``N = 500``; use ``N >= 1000``.

Failed samples
--------------
A sample whose evaluation failed (``status != 0``) counts as outside every
level (its ``f`` as ``+inf``): a failed proposal is rejected. They are counted
(``details["n_failed"]``, with a warning) but not bracketed as in naive Monte
Carlo and cross-entropy: counted dangerous, they would change the levels and
the chains themselves, so no second estimate follows from the same samples.

Seeds and resume
----------------
Every batch of at most :data:`~avrisk.rare.problem.SAMPLE_CHUNK` points is
evaluated through :meth:`EstimationContext.evaluate` as chunk 0 of its own
stage (1, 2, ... in the order of the run; a stage's per-sample seeds depend on
the stage, so no two proposals share one); its random numbers come from
``default_rng([seed, stage])``. The points are functions of the run seed and
of earlier values of ``f`` only: a resumed run asks for the recorded points
again and replays them, and the result does not depend on ``batch_size``.

References
----------
S.-K. Au, J. L. Beck. "Estimation of small failure probabilities in high
dimensions by subset simulation." Probabilistic Engineering Mechanics 16, 2001.
S. L. Cotter, G. O. Roberts, A. M. Stuart, D. White. "MCMC methods for
functions: modifying old algorithms to make them faster." Statistical Science
28, 2013 (pCN).
I. Papaioannou, W. Betz, K. Zwirglmaier, D. Straub. "MCMC algorithms for subset
simulation." Probabilistic Engineering Mechanics 41, 2015.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from pydantic import Field, ValidationInfo, field_validator
from scipy import stats

from avrisk.rare.black_box import estimate
from avrisk.rare.estimator import (
    DiagnosticTable,
    EstimationContext,
    EstimatorSettings,
    register_estimator,
)
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.final_stage import CONFIDENCE, MIN_RELIABLE_ESS
from avrisk.rare.problem import (
    SAMPLE_CHUNK,
    BatchFunction,
    RareEventProblem,
)
from avrisk.rare.results import Estimate, GammaEstimate, SearchConvergence

#: Acceptance rate the pCN step ``beta`` is adapted towards.
TARGET_ACCEPTANCE = 0.3
#: Gain of the adaptation: ``log beta`` moves by this times the acceptance error.
ADAPT_GAIN = 1.0
#: Smallest pCN step.
MIN_BETA = 1e-3
#: Standard normal quantile of the intervals' confidence (1.96 for 95%).
Z_CONFIDENCE = float(stats.norm.ppf(0.5 + CONFIDENCE / 2))
#: Rounds in a row in which no chain accepts before the run stops.
MAX_ROUNDS_WITHOUT_MOVE = 10

STDERR_METHOD = (
    "Au & Beck (2001) coefficient of variation: per level (1 - p_l) / (N p_l) "
    "(1 + gamma_l), gamma_l from the indicators' correlation along the chains, "
    "summed over levels taken as uncorrelated"
)
INTERVAL_METHOD = (
    "log-normal: normal on log p, Var(log p) = log(1 + cov^2), cov from the "
    "levels' survivor counts and the chains' correlation"
)


class SplittingError(ValueError):
    """The levels cannot reach ``gamma`` (the message says why)."""


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
        Most particle sets, the draws of ``P0`` included; not reaching
        ``gamma`` within them is a :class:`SplittingError`.
    n_moves : int, default=1
        pCN proposals per kept chain state (``> 1`` thins the chains).
    initial_beta : float, default=0.6
        pCN step of the first moves, in (0, 1]; then adapted.
    min_survivors : int, default=10
        Fewest of the first ``N`` draws of ``P0`` that must lie below a tie of
        ``f`` at their level (a plateau, e.g. a capped TTC); fewer, and the
        first set grows to ``plateau_draws N`` draws (*Plateaus*).
    plateau_draws : int, default=8
        Draws of a first set grown on a plateau, in multiples of ``N`` (1:
        never grown).
    """

    OMIT_IF_DEFAULT = ("min_survivors", "plateau_draws")

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

    @field_validator("p0_max")
    @classmethod
    def _at_least_p0(cls, p0_max: float, info: ValidationInfo) -> float:
        p0 = info.data.get("p0")
        if p0 is not None and p0_max < p0:
            raise ValueError(f"p0_max ({p0_max}) must be at least p0 ({p0})")
        return p0_max


class ParticleSet(NamedTuple):
    """The ``N`` particles of one level, by chain.

    Attributes
    ----------
    values : ndarray of shape (n_chains, max_length)
        ``f`` of chain ``j``'s state ``i`` (``+inf`` where its evaluation
        failed, NaN past the chain's end). Set 0 has ``N`` chains of length 1.
    level : float
        The next level chosen from these particles (``gamma`` on the last set).
    counted_from : int, default=0
        First chain whose states the set's factor counts: ``N`` for a first
        set grown on a plateau, whose first ``N`` draws decided that it grows
        (*Plateaus*), else 0.
    """

    values: FloatArray
    level: float
    counted_from: int = 0

    @property
    def flat(self) -> FloatArray:
        """The ``N`` values, chain after chain, shape (N,)."""
        return self.values[~np.isnan(self.values)]

    @property
    def counted(self) -> FloatArray:
        """The chains the factor counts, shape (n_chains - counted_from, max_length)."""
        return self.values[self.counted_from :]


class SplittingState(NamedTuple):
    """What the next level needs.

    Attributes
    ----------
    z : ndarray of shape (N, D)
        The last set's particles in standard-normal space, in the order of
        ``sets[-1].flat`` (shape (0, D) before the first step).
    sets : tuple of ParticleSet
        Every set so far (the estimate of every threshold reads them).
    beta : float
        pCN step for the next moves.
    reached : bool
        Whether the last set's level is ``gamma`` (the steps are over).
    n_stages : int
        Stages (evaluated batches) used so far.
    n_evals : int
        Calls of ``f`` so far.
    n_failed : int
        Evaluations that failed so far.
    rounds_without_move : int
        Rounds in a row in which no chain accepted.
    exhausted : bool, default=False
        Whether ``max_levels`` sets ended above ``gamma`` (the steps are over,
        without an estimate: :func:`exhausted_error`).
    """

    z: FloatArray
    sets: tuple[ParticleSet, ...]
    beta: float
    reached: bool
    n_stages: int
    n_evals: int
    n_failed: int
    rounds_without_move: int
    exhausted: bool = False


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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN becomes ``None``)."""
        return {
            k: None if isinstance(v, float) and math.isnan(v) else v
            for k, v in self._asdict().items()
        }


@register_estimator
class SubsetSimulation:
    """Subset simulation (module docstring) as an Estimator."""

    name = "splitting"
    label = "subset simulation"
    Settings: type[SplittingSettings] = SplittingSettings
    weighted = False
    budget_is_bound = True  # its levels may reach gamma before max_levels

    def __init__(self, settings: SplittingSettings) -> None:
        self.settings = settings

    def budget(self) -> int:
        """An upper bound for the progress bar: ``max_levels`` full sets.

        ``N`` draws (``plateau_draws N`` on a plateau), then at most ``N
        n_moves`` proposals per further set; a run that reaches ``gamma``
        sooner, as most do, makes fewer calls.
        """
        s = self.settings
        first = s.n_particles * s.plateau_draws
        return first + s.n_particles * (s.max_levels - 1) * s.n_moves

    def budget_not_redrawn(self) -> int:
        """All of :meth:`budget`: its points are drawn in standard space and moved."""
        return self.budget()

    def describe(self) -> str:
        """``"subset simulation, 2,000 particles per level, p0 0.1"``."""
        s = self.settings
        text = f"subset simulation, {s.n_particles:,} particles per level, p0 {s.p0:g}"
        return text + (f", {s.n_moves} moves per state" if s.n_moves > 1 else "")

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
        counted_from = 0
        if state.sets:
            moved = move_chains(state, problem, context, s.n_moves, s.n_particles)
        else:
            moved = _draw_p0(state, problem, context, s.n_particles)
            if s.plateau_draws > 1 and _on_plateau(moved.values, problem.gamma, s):
                counted_from = s.n_particles
                more = (s.plateau_draws - 1) * s.n_particles
                moved = _drawn_more(moved, problem, context, more)
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
        )
        return new_state, info

    def finalize(
        self,
        state: SplittingState,
        problem: RareEventProblem,
        context: EstimationContext,
    ) -> Estimate:
        """The product estimate and its Au & Beck error for every threshold.

        Raises
        ------
        SplittingError
            If ``max_levels`` sets did not reach ``gamma``.
        """
        if state.exhausted:
            raise exhausted_error(state, problem.gamma, self.settings.max_levels)
        if state.n_failed:
            warnings.warn(
                f"{state.n_failed} evaluations of f failed; subset simulation counts "
                "them outside every level (a failed proposal is rejected), with no "
                "bracket: fix what makes f fail (see the 'status' column)",
                UserWarning,
                stacklevel=2,
            )
        return levels_estimate(state, problem, self.settings.n_particles)

    def progress(self, info: SplittingInfo) -> str:
        """``"set 3: f <= 1.23, 212 survivors, accepted 31%, beta 0.42"``."""
        moves = (
            "independent draws"
            if math.isnan(info.acceptance)
            else f"accepted {info.acceptance:.0%}, beta {info.beta:.2g}"
        )
        return (
            f"set {info.index}: f <= {info.level:.3g}, "
            f"{info.n_survivors} survivors, {moves}"
        )

    def checkpoint(
        self, state: SplittingState, infos: Sequence[SplittingInfo]
    ) -> dict[str, Any]:
        """The levels so far (for inspection and reports)."""
        return {
            "levels_done": len(state.sets),
            "n_evals": state.n_evals,
            "beta": state.beta,
            "levels": [i.to_dict() for i in infos],
        }

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """Levels of ``f``, survivors, acceptance and ``beta`` per set.

        One table per independent replicate of the levels (each numbers its
        sets from 0), titled with its number when there are several.
        """
        history = estimate.get("history") or []
        columns = ("set", "level", "survivors", "acceptance", "beta")
        keys = ("index", "level", "n_survivors", "acceptance", "beta")
        replicates = sorted({h.get("replicate", 0) for h in history})
        return [
            DiagnosticTable(
                "Subset simulation levels"
                + (f", replicate {r + 1}" if len(replicates) > 1 else ""),
                columns,
                [
                    tuple(h[k] for k in keys)
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
        """A level held by fewer than ``MIN_RELIABLE_ESS`` particles (a plateau).

        Its factor then rests on a handful of draws and its chains on as
        many seeds: the interval, from normal approximations, is too narrow.
        """
        survivors = (estimate.get("details") or {}).get("survivors") or []
        few = [int(k) for k in survivors[:-1] if k < MIN_RELIABLE_ESS]
        if not few:
            return ()
        return (
            f"a level of the search held only {min(few)} particles below it (f "
            "ties on a plateau?): its interval is likely too narrow",
        )


def exhausted_error(
    state: SplittingState, gamma: float, max_levels: int
) -> SplittingError:
    """The error of levels that ``max_levels`` sets did not bring to ``gamma``."""
    level = state.sets[-1].level
    p_so_far = math.prod(_factors(state.sets))
    return SplittingError(
        f"after max_levels={max_levels} levels the level is f <= {level:g}, still "
        f"above gamma = {gamma:g} (P0(f <= {level:g}) is about {p_so_far:.2g}): the "
        "event may be impossible, or rarer than that many levels reach; raise "
        "max_levels (or p0)"
    )


def levels_estimate(
    state: SplittingState, problem: RareEventProblem, n_particles: int
) -> Estimate:
    """Subset simulation's estimate of every threshold from a run's particle sets.

    ``details`` holds the levels, the survivors of each set, their c.o.v.s,
    the first set's draws, whether the answer is a bound only (no particle at
    or below ``gamma``: *Plateaus*) and the failed evaluations.
    """
    by_gamma = {problem.gamma: _estimate_at(state.sets, problem.gamma)}
    for g in problem.thresholds[1:]:
        by_gamma[g] = _estimate_at(state.sets, g, by_gamma[problem.gamma].ci[1])
    return Estimate(
        method="subset_simulation",
        gamma=problem.gamma,
        by_gamma=by_gamma,
        n_evals=state.n_evals,
        details={
            "levels": [ps.level for ps in state.sets],
            "survivors": _survivors(state.sets),
            "level_cov": [
                math.sqrt(level_cov_squared(ps.counted, ps.level)) for ps in state.sets
            ],
            "n_particles": n_particles,
            "first_set_draws": state.sets[0].flat.size,
            "bound_only": by_gamma[problem.gamma].n_hits == 0,
            "n_failed": state.n_failed,
            "stderr_method": STDERR_METHOD,
        },
    )


def next_level(
    values: FloatArray,
    current: float,
    gamma: float,
    p0: float,
    p0_max: float,
) -> float | None:
    """The next level from a particle set's ``f`` (*Ties* in the module docstring).

    Parameters
    ----------
    values : ndarray of shape (N,)
        ``f`` of the set's particles (``+inf`` for failed ones), all at or
        below ``current``.
    current : float
        Level the set is conditioned on (``inf`` for draws of ``P0``).
    gamma : float
        Threshold of the event.
    p0, p0_max : float
        Quantile level; largest share of survivors ties may leave.

    Returns
    -------
    float or None
        ``gamma`` when the ``p0``-quantile is at or below it, else a level
        below ``current``; None when none can fall below it (every particle
        at ``current``: a plateau).

    Examples
    --------
    >>> values = np.array([0.0, 1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    >>> float(next_level(values, np.inf, -1.0, p0=0.2, p0_max=0.5))  # 5 survivors
    1.0
    >>> float(next_level(values, np.inf, -1.0, p0=0.2, p0_max=0.4))  # below the ties
    0.0
    >>> print(next_level(np.full(10, 7.0), 7.0, -1.0, p0=0.2, p0_max=0.5))
    None
    """
    quantile = float(np.quantile(values, p0, method="inverted_cdf"))
    if quantile > gamma and np.count_nonzero(values <= quantile) > p0_max * values.size:
        below = values[values < quantile]
        if below.size:
            quantile = float(below.max())
    if max(quantile, gamma) >= current:
        return None
    return max(quantile, gamma)


def level_cov_squared(values: FloatArray, threshold: float) -> float:
    """Au & Beck's squared c.o.v. of a set's share of ``f <= threshold``.

    Parameters
    ----------
    values : ndarray of shape (n_chains, max_length)
        ``f`` by chain, NaN past each chain's end (:class:`ParticleSet`).
    threshold : float

    Returns
    -------
    float
        ``(1 - p) / (N p) (1 + gamma)`` with ``gamma = 2 sum_k (pairs_k / N)
        rho(k)`` over the lags ``k`` within chains; 0 when ``p`` is 0 or 1.
    """
    present = ~np.isnan(values)
    hits = values <= threshold
    n = int(present.sum())
    p = np.count_nonzero(hits) / n
    if p in (0.0, 1.0):
        return 0.0
    variance = p * (1 - p)
    correlation = 0.0
    for lag in range(1, values.shape[1]):
        pairs = np.count_nonzero(present[:, :-lag] & present[:, lag:])
        both = np.count_nonzero(hits[:, :-lag] & hits[:, lag:])
        correlation += pairs / n * (both / pairs - p * p) / variance
    # chains of pCN states are positively correlated; a negative estimate is
    # noise, and would make the interval narrower than independent draws'
    return (1 - p) / (n * p) * max(1.0, 1 + 2 * correlation)


def _survivors(sets: Sequence[ParticleSet]) -> list[int]:
    """Each set's number of particles at or below its level."""
    return [int(np.count_nonzero(ps.flat <= ps.level)) for ps in sets]


def _factors(sets: Sequence[ParticleSet]) -> list[float]:
    """Each set's factor: the share of its counted states at or below its level."""
    return [_share(ps.counted, ps.level) for ps in sets]


def _share(values: FloatArray, threshold: float) -> float:
    """Share of the present (non-NaN) ``values`` at or below ``threshold``."""
    present = values[~np.isnan(values)]
    return np.count_nonzero(present <= threshold) / present.size


def _on_plateau(values: FloatArray, gamma: float, settings: SplittingSettings) -> bool:
    """Whether draws of ``P0`` hold too few particles below a tie (*Plateaus*).

    Parameters
    ----------
    values : ndarray of shape (N_0, 1)
        ``f`` of the first set's draws.
    gamma : float
    settings : SplittingSettings
        ``p0``, ``p0_max`` and ``min_survivors``.
    """
    flat = values.ravel()
    level = next_level(flat, math.inf, gamma, settings.p0, settings.p0_max)
    if level is None:  # every draw at +inf
        return True
    # without ties the level keeps at least p0 N survivors: fewer means a tie
    survivors = int(np.count_nonzero(flat <= level))
    few = min(settings.min_survivors, settings.p0 * flat.size)
    return level > gamma and (survivors < few or survivors == flat.size)


def lognormal_interval(p: float, cov_squared: float) -> tuple[float, float]:
    """``p``'s interval, normal on ``log p`` with ``Var(log p) = log(1 + cov^2)``.

    The upper end is at most 1.
    """
    half = Z_CONFIDENCE * math.sqrt(math.log1p(cov_squared))
    return (p * math.exp(-half), min(1.0, p * math.exp(half)))


def _estimate_at(
    sets: Sequence[ParticleSet], g: float, bound: float = 1.0
) -> GammaEstimate:
    """``P0(f <= g)`` from the deepest set conditioned on a level ``>= g``.

    With no particle of that set at or below ``g``, ``p`` is 0 and the
    interval reaches up to the upper end of the factors above times the exact
    upper bound of a share of 0 of that set, or ``bound`` if lower (the
    interval of ``gamma``, for ``g`` below it).
    """
    deepest = max(i for i in range(len(sets)) if i == 0 or sets[i - 1].level >= g)
    above = sets[:deepest]
    counted = sets[deepest].counted
    n_last = int(np.count_nonzero(~np.isnan(counted)))
    n_hits = int(np.count_nonzero(counted <= g))
    p_above = math.prod(_factors(above))
    p = p_above * n_hits / n_last
    cov_squared = sum(
        level_cov_squared(ps.counted, ps.level) for ps in above
    ) + level_cov_squared(counted, g)
    if n_hits:
        ci = lognormal_interval(p, cov_squared)
    else:  # the upper ends of the factors above and of a share of 0
        cov_above = cov_squared - level_cov_squared(counted, g)
        half = Z_CONFIDENCE * math.sqrt(math.log1p(cov_above))
        upper_above = p_above * math.exp(half)
        upper = -math.expm1(math.log((1 - CONFIDENCE) / 2) / n_last)
        ci = (0.0, min(bound, upper_above * upper))
    return GammaEstimate(
        gamma=g,
        p=p,
        stderr=p * math.sqrt(cov_squared),
        ci=ci,
        n_hits=n_hits,
        ess=float(n_hits),
        n_samples=n_last,
        confidence=CONFIDENCE,
        interval=INTERVAL_METHOD,
    )


class _Moved(NamedTuple):
    """A new particle set and what making it cost (see :class:`SplittingState`)."""

    z: FloatArray
    values: FloatArray
    acceptance: float
    n_calls: int
    beta: float
    n_stages: int
    n_failed: int
    rounds_without_move: int


def _draw_p0(
    state: SplittingState, problem: RareEventProblem, context: EstimationContext, n: int
) -> _Moved:
    """Set 0: ``n`` draws of ``P0`` (standard normals mapped by the base)."""
    empty = _Moved(
        np.empty((0, problem.base.dim)),
        np.empty((0, 1)),
        math.nan,
        0,
        state.beta,
        state.n_stages,
        0,
        state.rounds_without_move,
    )
    return _drawn_more(empty, problem, context, n)


def _drawn_more(
    first: _Moved, problem: RareEventProblem, context: EstimationContext, n: int
) -> _Moved:
    """The first set with ``n`` more draws of ``P0``, a stage of their own."""
    stage = first.n_stages + 1
    z = np.random.default_rng([context.seed, stage]).standard_normal(
        (n, problem.base.dim)
    )
    values, n_failed, n_stages = _evaluate(problem, context, z, stage)
    return first._replace(
        z=np.concatenate([first.z, z]),
        values=np.concatenate([first.values, values[:, None]]),
        n_calls=first.n_calls + n,
        n_stages=first.n_stages + n_stages,
        n_failed=first.n_failed + n_failed,
    )


def move_chains(
    state: SplittingState,
    problem: RareEventProblem,
    context: EstimationContext,
    n_moves: int,
    n: int,
) -> _Moved:
    """The next set, ``n`` states of chains from the last set's survivors (pCN)."""
    last = state.sets[-1]
    flat = last.flat
    seeds = np.flatnonzero(flat <= last.level)
    n_chains = seeds.size
    lengths = np.full(n_chains, n // n_chains)
    lengths[: n % n_chains] += 1  # the longer chains first: who moves is a prefix
    z_chain = np.zeros((n_chains, lengths[0], state.z.shape[1]))
    values = np.full((n_chains, lengths[0]), np.nan)
    z_chain[:, 0], values[:, 0] = state.z[seeds], flat[seeds]
    beta, n_stages, stuck = state.beta, state.n_stages, state.rounds_without_move
    accepted = proposed = n_failed = 0
    for position in range(1, lengths[0]):
        moving = int(np.count_nonzero(lengths > position))
        z, f = z_chain[:moving, position - 1], values[:moving, position - 1]
        for _ in range(n_moves):
            stage = n_stages + 1
            eps = np.random.default_rng([context.seed, stage]).standard_normal(z.shape)
            proposal = math.sqrt(1 - beta * beta) * z + beta * eps
            f_new, failed, used = _evaluate(problem, context, proposal, stage)
            accept = f_new <= last.level
            z = np.where(accept[:, None], proposal, z)
            f = np.where(accept, f_new, f)
            n_accepted = int(np.count_nonzero(accept))
            beta = _adapted(beta, n_accepted, moving, n_chains)
            stuck = 0 if n_accepted else stuck + 1
            if stuck >= MAX_ROUNDS_WITHOUT_MOVE and beta == MIN_BETA:
                raise SplittingError(
                    f"no chain accepted a pCN proposal in {stuck} rounds in a row at "
                    f"level f <= {last.level:g}, with the smallest step beta = "
                    f"{MIN_BETA:g}: the set below the level may have no volume, or f "
                    "may jump there (a stochastic f whose outcome hardly depends on x?)"
                )
            accepted += n_accepted
            proposed += moving
            n_failed += failed
            n_stages += used
        z_chain[:moving, position], values[:moving, position] = z, f
    present = ~np.isnan(values)
    return _Moved(
        z_chain[present],
        values,
        accepted / proposed if proposed else math.nan,
        proposed,
        beta,
        n_stages,
        n_failed,
        stuck,
    )


def _adapted(beta: float, n_accepted: int, n_proposed: int, n_chains: int) -> float:
    """``beta`` after a round of ``n_proposed`` proposals from ``n_chains`` chains.

    ``log beta`` moves by ``ADAPT_GAIN`` times the acceptance rate's error,
    weighted by the share of the chains that proposed (a round of a few chains
    at a level's end moves it little).
    """
    error = (n_accepted - TARGET_ACCEPTANCE * n_proposed) / n_chains
    return float(np.clip(beta * math.exp(ADAPT_GAIN * error), MIN_BETA, 1.0))


def _evaluate(
    problem: RareEventProblem,
    context: EstimationContext,
    z: FloatArray,
    first_stage: int,
) -> tuple[FloatArray, int, int]:
    """``f`` at ``T^-1(z)``, at most ``SAMPLE_CHUNK`` rows per stage.

    Returns
    -------
    values : ndarray of shape (n,)
        ``+inf`` where the evaluation failed.
    n_failed : int
    n_stages : int
        Stages used, from ``first_stage`` on.
    """
    parts, n_failed = [], 0
    starts = range(0, len(z), SAMPLE_CHUNK)
    for k, start in enumerate(starts):
        x = problem.base.from_standard_normal(z[start : start + SAMPLE_CHUNK])
        values, failed = context.evaluate(problem, x, first_stage + k, 0)
        parts.append(np.where(failed, np.inf, values))
        n_failed += int(np.count_nonzero(failed))
    return np.concatenate(parts), n_failed, len(starts)


def subset_simulation(
    f: BatchFunction, base: ExponentialFamily, gamma: float, **options: Any
) -> Estimate:
    """Subset simulation: ``estimate("splitting", f, base, gamma, **options)``."""
    return estimate("splitting", f, base, gamma, **options)
