"""Problems with exact answers and conformance checks for avrisk components."""

from avrisk.testing.checks import check_estimator, check_family
from avrisk.testing.problems import (
    AnalyticProblem,
    beta_sum_cdf,
    beta_sum_problem,
    four_branch_problem,
    gaussian_linear_problem,
    mixed_problem,
)

__all__ = [
    "AnalyticProblem",
    "beta_sum_cdf",
    "beta_sum_problem",
    "check_estimator",
    "check_family",
    "four_branch_problem",
    "gaussian_linear_problem",
    "mixed_problem",
]
