"""The estimator protocol: every rare-event estimator, behind one interface.

After BlackJAX's ``init`` / ``step`` pairs with State and Info tuples, an
estimator is an object configured by its own validated settings that a driver
runs as::

    state = estimator.init(problem)
    while not estimator.done(state):
        state, info = estimator.step(state, problem, context)   # a CE iteration,
        ...                                                      # a splitting level
    estimate = estimator.finalize(state, problem, context)

``State`` is whatever the next step needs (a proposal, a particle set);
``Info`` the diagnostics of one step (``to_dict()`` for a record). Every call
of ``f`` goes through the ``context``
(:class:`~avrisk.rare.estimation_context.EstimationContext`), which draws a
stage's samples, hands them to the evaluator and records or replays each
chunk, so a driver (:mod:`avrisk.pipeline`) can show progress, checkpoint and
resume any estimator the same way. Samples need not carry importance weights:
a splitting estimator evaluates MCMC moves through the context's
:meth:`~avrisk.rare.estimation_context.EstimationContext.evaluate`.

Estimators are registered by name (:func:`register_estimator`,
:func:`get_estimator`); a new one is one module that defines its settings
model, its state and info, and the five methods, plus one registration line.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, ClassVar, Generic, Protocol, Self, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from avrisk.rare.diagnostic_table import DiagnosticTable
from avrisk.rare.directional_audit import audit_calls, with_directional_audit
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.problem import RareEventProblem
from avrisk.rare.results import Estimate, SearchConvergence
from avrisk.registry import Registry

__all__ = [
    "DEFAULT_METHOD",
    "DiagnosticTable",
    "Estimator",
    "EstimatorSettings",
    "ESTIMATORS",
    "estimator_names",
    "get_estimator",
    "no_doubts",
    "planned_budget",
    "register_estimator",
    "run_estimator",
]

State = TypeVar("State")
Info = TypeVar("Info")

#: The estimator a run uses unless told otherwise: the best of the coverage
#: benchmark on both simulator scenarios and on the analytic problems'
#: high-dimensional cases (BENCHMARKS.md, "Coverage"); ``"ce"`` is the paper's.
DEFAULT_METHOD = "splitting_is"


class EstimatorSettings(BaseModel):
    """Base of every estimator's settings model (validated, immutable).

    ``OMIT_IF_DEFAULT`` names settings left out of :meth:`recorded` while they
    hold their default, so that adding an option does not change how earlier
    runs are recorded. ``OMIT_AT_FORMER_DEFAULT`` does the same for settings
    whose default has changed since, while they hold the former default: a run
    recorded before the change still resumes with that value given, and one
    at the new default is recorded with it, so the two are never taken for
    each other.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    OMIT_IF_DEFAULT: ClassVar[tuple[str, ...]] = ()
    OMIT_AT_FORMER_DEFAULT: ClassVar[dict[str, Any]] = {}

    @classmethod
    def validated(cls, **values: Any) -> EstimatorSettings:
        """The settings from ``values``, or a ValueError naming each bad one.

        Examples
        --------
        >>> from avrisk.rare.cross_entropy import CESettings
        >>> CESettings.validated(rho=1.5)
        Traceback (most recent call last):
        ...
        ValueError: rho: Input should be less than 1; got 1.5
        """
        try:
            return cls(**values)
        except ValidationError as err:
            problems = "; ".join(
                f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
                + (f"; got {e['input']!r}" if e["type"] != "extra_forbidden" else "")
                for e in err.errors()
            )
            raise ValueError(problems) from None

    @classmethod
    def overridden(
        cls, settings: EstimatorSettings | None, caller: str, /, **overrides: Any
    ) -> Self:
        """``settings`` (default: the defaults) with ``overrides`` by name, validated.

        How :func:`~avrisk.rare.black_box.estimate` takes a method's settings:
        a settings object, or any of its settings as keyword arguments of
        ``caller``, or both.

        Raises
        ------
        TypeError
            If ``settings`` is not of this model, or a name is not one of its
            settings (as for any unexpected keyword argument of ``caller``).
        ValueError
            If a setting is invalid (:meth:`validated`).

        Examples
        --------
        >>> from avrisk.rare.cross_entropy import CESettings
        >>> s = CESettings.overridden(CESettings(rho=0.1), "f", n_iter=5)
        >>> s.rho, s.n_iter, s.n_final
        (0.1, 5, 100000)
        >>> CESettings.overridden(None, "f", n_iters=5)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        TypeError: f() got an unexpected keyword argument 'n_iters' (the settings...
        """
        if settings is not None and not isinstance(settings, cls):
            raise TypeError(
                f"{caller}() takes settings of {cls.__name__}; "
                f"got {type(settings).__name__}"
            )
        for name in overrides:
            if name not in cls.model_fields:
                raise TypeError(
                    f"{caller}() got an unexpected keyword argument {name!r} "
                    f"(the settings of {cls.__name__}: {', '.join(cls.model_fields)})"
                )
        given = (
            {}
            if settings is None
            else {k: getattr(settings, k) for k in cls.model_fields}
        )
        return cls.validated(**{**given, **overrides})  # type: ignore[return-value]

    def recorded(self) -> dict[str, Any]:
        """The settings that define a run, for its record (JSON types)."""
        out = self.model_dump(mode="json")
        for name in self.OMIT_IF_DEFAULT:
            if out[name] == type(self).model_fields[name].default:
                out.pop(name)
        for name, former in self.OMIT_AT_FORMER_DEFAULT.items():
            if out[name] == former:
                out.pop(name)
        return out


class Estimator(Protocol, Generic[State, Info]):
    """What every estimator implements (see the module docstring).

    Class attributes
    ----------------
    name : str
        Registry name (``"ce"``, ``"naive"``).
    label : str
        Human name for tables and reports (``"cross-entropy"``).
    Settings : type of EstimatorSettings
        Its settings model; the instance's are in ``settings``.
    weighted : bool
        Whether its hits carry importance weights (their ESS and Pareto k
        then say how far its standard error can be trusted).
    decomposable : bool
        Whether its estimate is the mean of ``w 1{f <= gamma}`` over its final
        stage (``w = 1`` for naive sampling): then ``p`` splits exactly by any
        per-sample label (:mod:`avrisk.pipeline.mechanisms`).
    budget_is_bound : bool
        Whether :meth:`budget` is an upper bound rather than the calls it
        makes (subset simulation's levels usually reach ``gamma`` before
        ``max_levels``): a plan then says "at most".
    searches : bool
        Whether it searches for the event, and so may miss a failure region
        its search never reached: :func:`run_estimator` then checks it by
        rays where ``X`` is low-dimensional
        (:mod:`avrisk.rare.directional_audit`). An estimator that does not
        say is taken to search; naive sampling does not.
    """

    name: ClassVar[str]
    label: ClassVar[str]
    Settings: ClassVar[type[EstimatorSettings]]
    weighted: ClassVar[bool]
    decomposable: ClassVar[bool]
    budget_is_bound: ClassVar[bool]
    searches: ClassVar[bool]
    settings: EstimatorSettings

    def budget(self) -> int:
        """Calls of ``f`` it plans, or at most makes (a progress bar's total)."""
        ...

    def budget_not_redrawn(self) -> int:
        """Calls of :meth:`budget` at points no recorded proposal draws again.

        Fresh draws of a stage's proposal can be drawn again from its record
        (:mod:`avrisk.rare.proposals`), so a run directory need not store
        their large blocks; other points (subset simulation's: ``P0`` drawn in
        standard space, pCN moves) are stored in full. A plan's disk estimate
        counts them apart.
        """
        ...

    def describe(self) -> str:
        """One line: the method and its budget (``"CE 20x5,000 + 100,000"``)."""
        ...

    def init(self, problem: RareEventProblem) -> State:
        """State before the first step."""
        ...

    def done(self, state: State) -> bool:
        """Whether the steps are over (``finalize`` comes next)."""
        ...

    def step(
        self, state: State, problem: RareEventProblem, context: EstimationContext
    ) -> tuple[State, Info]:
        """One step (a search iteration, a level) and its diagnostics."""
        ...

    def finalize(
        self, state: State, problem: RareEventProblem, context: EstimationContext
    ) -> Estimate:
        """The estimate (``wall_time_s`` is set by :func:`run_estimator`)."""
        ...

    def progress(self, info: Info) -> str:
        """A short status line after a step, for a progress display."""
        ...

    def checkpoint(self, state: State, infos: Sequence[Info]) -> dict[str, Any]:
        """JSON-ready record of the state and the steps so far."""
        ...

    @staticmethod
    def diagnostics(estimate: dict[str, Any]) -> list[DiagnosticTable]:
        """Tables for a report, from a summary's ``estimate`` dictionary."""
        ...

    @staticmethod
    def convergence(estimate: dict[str, Any], gamma: float) -> SearchConvergence | None:
        """Whether its search reached ``gamma`` and held it, from a summary's estimate.

        None for an estimator whose steps do not search for the event (naive
        Monte Carlo) or always end at ``gamma`` (subset simulation).
        """
        ...

    @staticmethod
    def stage_label(estimate: dict[str, Any], stage: int) -> str:
        """The step that drew the samples of ``stage``, in its diagnostics' words.

        ``"CE iteration 3"``, ``"replicate 2, set 3"``, ``"the final stage"``: a
        report labels a failure with the step its diagnostic plot shows, so
        that the two can be read together.
        """
        ...

    @staticmethod
    def doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
        """Reasons, from a summary's estimate, not to take its interval at its word.

        What the estimator knows beyond the diagnostics every estimate has
        (:func:`avrisk.rare.trust.trust_at`): independent replicates that
        disagree, a level held by a handful of particles; :func:`no_doubts`
        for one that knows nothing more.
        """
        ...


def no_doubts(estimate: dict[str, Any], gamma: float) -> tuple[str, ...]:
    """:meth:`Estimator.doubts` of an estimator with nothing to add: none."""
    return ()


#: The estimators by name (:class:`~avrisk.registry.Registry`): registered by
#: :func:`register_estimator`, built with their settings by :func:`get_estimator`.
ESTIMATORS = Registry("estimator")
estimator_names = ESTIMATORS.names
estimator_class = ESTIMATORS.get


def register_estimator(cls: type[Estimator[Any, Any]]) -> type[Estimator[Any, Any]]:
    """Make an estimator class available by its ``name`` (usable as decorator)."""
    ESTIMATORS.register(cls.name, cls, description=cls.label)
    return cls


def get_estimator(name: str, **settings: Any) -> Estimator[Any, Any]:
    """Build the estimator ``name`` with validated ``settings``.

    Raises
    ------
    KeyError
        If ``name`` is not registered (the message lists the known names).
    ValueError
        If a setting is unknown or invalid (the message names it).
    """
    cls = estimator_class(name)
    try:
        return cls(cls.Settings.validated(**settings))
    except ValueError as err:
        raise ValueError(f"estimator {name!r}: {err}") from None


def planned_budget(estimator: Estimator[Any, Any], dim: int | None = None) -> int:
    """Calls of ``f`` the estimator plans before it grows its budget.

    An estimator that may grow its budget as the event turns out harder
    (subset simulation's regrown replicates) says what it plans without
    growing by a ``planned_budget()`` method; for the others it is
    :meth:`Estimator.budget`. With ``dim`` (of ``X``), the check by rays
    that :func:`run_estimator` adds in low dimension is counted too.
    """
    planned = int(getattr(estimator, "planned_budget", estimator.budget)())
    return planned + (0 if dim is None else audit_calls(estimator, dim))


def run_estimator(
    estimator: Estimator[Any, Info],
    problem: RareEventProblem,
    context: EstimationContext,
    *,
    callback: Callable[[Info, Any], None] | None = None,
    directional_audit: bool = True,
) -> Estimate:
    """Run any estimator to its estimate (the loop of the module docstring).

    Parameters
    ----------
    estimator : Estimator
    problem : RareEventProblem
    context : EstimationContext
    callback : callable, optional
        ``callback(info, state)`` after every step (progress, checkpoints).
    directional_audit : bool, default=True
        Whether an estimator that searches is checked by rays where ``X`` is
        low-dimensional (below); False compares estimators at exactly their
        own calls.

    Returns
    -------
    Estimate
        With the steps' infos as ``history`` and ``wall_time_s`` measured here;
        for an estimator that searches, on ``X`` of at most
        :data:`~avrisk.rare.directional_audit.MAX_DIM` dimensions, checked by
        rays after its own stages (``details["directional"]``, its calls in
        ``n_evals``; the estimate itself is unchanged).
    """
    start = time.perf_counter()
    state = estimator.init(problem)
    history = []
    while not estimator.done(state):
        state, info = estimator.step(state, problem, context)
        history.append(info)
        if callback is not None:
            callback(info, state)
    estimate = estimator.finalize(state, problem, context)
    if directional_audit:
        estimate = with_directional_audit(estimator, estimate, problem, context)
    return replace(
        estimate, history=tuple(history), wall_time_s=time.perf_counter() - start
    )
