"""The rare-event estimation engine. It knows nothing of cars.

It sees a base distribution ``P0`` (an exponential family, or a product of
them) and a batched black-box function ``f``, and estimates ``P0(f(X) <=
gamma)`` for thresholds where naive Monte Carlo is hopeless. The one entry
point is :func:`estimate`: ``estimate(method, f, base, gamma, **settings)``.
"""

from avrisk.rare.black_box import estimate
from avrisk.rare.cross_entropy import CrossEntropy, cross_entropy
from avrisk.rare.cross_entropy_search import CEState
from avrisk.rare.estimation_context import EstimationContext
from avrisk.rare.estimator import (
    Estimator,
    estimator_names,
    get_estimator,
    run_estimator,
)
from avrisk.rare.evaluation import EvalResult, EvalTask, Evaluator, LocalEvaluator
from avrisk.rare.families import (
    ExponentialFamily,
    FixedCovNormal,
    Product,
    ScaledBeta,
    StandardSpaceShift,
)
from avrisk.rare.final_stage import UnreliableEstimateWarning, ZeroHitsWarning
from avrisk.rare.mixture import MixtureCrossEntropy, mixture_ce
from avrisk.rare.mixture_em import MixtureProposal
from avrisk.rare.naive_mc import NaiveMC, naive_mc
from avrisk.rare.problem import InvalidOutputError, RareEventProblem
from avrisk.rare.results import CEInfo, Estimate, GammaEstimate, MixtureInfo
from avrisk.rare.splitting import SubsetSimulation, subset_simulation
from avrisk.rare.splitting_importance import SplittingImportanceSampling, splitting_is
from avrisk.rare.splitting_levels import SplittingError
from avrisk.rare.stages import StageBatch, run_stage

__all__ = [
    "CEInfo",
    "CEState",
    "CrossEntropy",
    "EstimationContext",
    "Estimator",
    "EvalResult",
    "EvalTask",
    "Evaluator",
    "LocalEvaluator",
    "MixtureCrossEntropy",
    "MixtureInfo",
    "MixtureProposal",
    "NaiveMC",
    "Estimate",
    "ExponentialFamily",
    "FixedCovNormal",
    "GammaEstimate",
    "InvalidOutputError",
    "Product",
    "RareEventProblem",
    "ScaledBeta",
    "StandardSpaceShift",
    "SplittingError",
    "SplittingImportanceSampling",
    "StageBatch",
    "SubsetSimulation",
    "UnreliableEstimateWarning",
    "ZeroHitsWarning",
    "cross_entropy",
    "estimate",
    "estimator_names",
    "get_estimator",
    "mixture_ce",
    "naive_mc",
    "run_estimator",
    "run_stage",
    "splitting_is",
    "subset_simulation",
]
