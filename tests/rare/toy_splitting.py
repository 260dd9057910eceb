"""A toy estimator that is not an importance sampler: subset simulation.

The whole of a new estimator behind the engine's protocol, in one module: its
settings model, state, info, the five methods and one registration line. It
moves particles of a standard normal ``P0`` by preconditioned Crank-Nicolson
MCMC (which leaves ``N(0, I)`` invariant) through levels set at the ``p0``
quantile of ``f``, and estimates ``p = p0^(L) * (share of the last level below
gamma)``. Its samples carry no weights; they are evaluated through
``EstimationContext.evaluate``, so they are recorded and replayed on resume.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from pydantic import Field

from avrisk.rare.estimator import EstimatorSettings, register_estimator
from avrisk.rare.final_stage import CONFIDENCE
from avrisk.rare.intervals import normal_interval
from avrisk.rare.results import Estimate, GammaEstimate


class ToySettings(EstimatorSettings):
    n_particles: int = Field(1000, ge=10)
    p0: float = Field(0.1, gt=0.0, lt=1.0)
    max_levels: int = Field(12, ge=1)
    beta: float = Field(0.6, gt=0.0, le=1.0)  # pCN step


class ToyState(NamedTuple):
    x: np.ndarray  # (N, D) particles, standard normal space
    f: np.ndarray  # (N,)
    level: float  # current level (inf before the first)
    reached: bool  # the level is gamma: the last level
    n_levels: int
    n_evals: int


class ToyInfo(NamedTuple):
    level: float
    accepted: float

    def to_dict(self):
        return self._asdict()


@register_estimator
class ToySplitting:
    name = "toy_splitting"
    label = "toy subset simulation"
    Settings = ToySettings
    weighted = False

    def __init__(self, settings):
        self.settings = settings

    def budget(self):
        s = self.settings
        return s.n_particles * (1 + s.max_levels)

    def describe(self):
        return f"toy subset simulation, {self.settings.n_particles} particles"

    def init(self, problem):
        empty = np.empty((0, problem.base.dim))
        return ToyState(empty, np.empty(0), math.inf, False, 0, 0)

    def done(self, state):
        return state.reached or state.n_levels > self.settings.max_levels

    def step(self, state, problem, context):
        s = self.settings
        stage = state.n_levels + 1
        rng = np.random.default_rng([context.seed, stage])
        if state.n_levels == 0:  # level 0: plain draws of P0
            x = rng.standard_normal((s.n_particles, problem.base.dim))
            f, _ = context.evaluate(problem, x, stage, 0)
            accepted = 1.0
        else:  # seeds below the level, resampled, one pCN move each
            seeds = np.flatnonzero(state.f <= state.level)
            pick = rng.choice(seeds, s.n_particles)
            x0, f0 = state.x[pick], state.f[pick]
            move = math.sqrt(1 - s.beta**2) * x0 + s.beta * rng.standard_normal(
                x0.shape
            )
            f1, _ = context.evaluate(problem, move, stage, 0)
            keep = f1 <= state.level
            x = np.where(keep[:, None], move, x0)
            f = np.where(keep, f1, f0)
            accepted = float(keep.mean())
        level = max(problem.gamma, float(np.quantile(f, s.p0, method="inverted_cdf")))
        reached = level <= problem.gamma
        n_evals = state.n_evals + s.n_particles
        new = ToyState(x, f, level, reached, state.n_levels + 1, n_evals)
        return new, ToyInfo(level, accepted)

    def finalize(self, state, problem, context):
        s = self.settings
        by_gamma = {}
        for g in problem.thresholds:
            share = float(np.mean(state.f <= g))
            p = s.p0 ** (state.n_levels - 1) * share
            rel = math.sqrt(state.n_levels * (1 - s.p0) / (s.n_particles * s.p0) * 3)
            se = p * rel
            by_gamma[g] = GammaEstimate(
                gamma=g,
                p=p,
                stderr=se,
                ci=normal_interval(p, se, CONFIDENCE),
                n_hits=int(np.count_nonzero(state.f <= g)),
                ess=float(np.count_nonzero(state.f <= g)),
                n_samples=s.n_particles,
            )
        return Estimate(
            method=self.name,
            gamma=problem.gamma,
            by_gamma=by_gamma,
            n_evals=state.n_evals,
            details={"levels": state.n_levels},
        )

    def progress(self, info):
        return f"level {info.level:.3g}, accepted {info.accepted:.0%}"

    def checkpoint(self, state, infos):
        return {"levels": [i.to_dict() for i in infos]}

    @staticmethod
    def diagnostics(estimate: dict[str, Any]):
        return []
