"""The rare-event estimation engine. It knows nothing of cars.

It sees a base distribution ``P0`` (an exponential family, or a product of
them) and a batched black-box function ``f``, and estimates ``P0(f(X) <=
gamma)`` for thresholds where naive Monte Carlo is hopeless.
"""

from avrisk.rare.cross_entropy import CEState, ce_init, ce_step, cross_entropy
from avrisk.rare.families import ExponentialFamily, FixedCovNormal, Product, ScaledBeta
from avrisk.rare.final_stage import UnreliableEstimateWarning, ZeroHitsWarning
from avrisk.rare.naive_mc import naive_mc
from avrisk.rare.problem import InvalidOutputError, RareEventProblem
from avrisk.rare.results import CEInfo, Estimate, GammaEstimate
from avrisk.rare.stages import StageBatch, run_stage

__all__ = [
    "CEInfo",
    "CEState",
    "Estimate",
    "ExponentialFamily",
    "FixedCovNormal",
    "GammaEstimate",
    "InvalidOutputError",
    "Product",
    "RareEventProblem",
    "ScaledBeta",
    "StageBatch",
    "UnreliableEstimateWarning",
    "ZeroHitsWarning",
    "ce_init",
    "ce_step",
    "cross_entropy",
    "naive_mc",
    "run_stage",
]
