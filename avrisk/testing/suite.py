"""A suite of rare-event problems with exact answers, for benchmarks (issue 46).

Each problem is an :class:`~avrisk.testing.problems.AnalyticProblem`: a base
``P0`` (an engine family), a batched ``f`` of shape ``(n, D) -> (n,)``, a
threshold ``gamma`` and ``p = P0(f(X) <= gamma)`` computed independently of
``f`` (``reference`` says how; ``p_rel_error`` is the reference's own relative
standard error, 0 for closed forms and quadratures). The families aim at the
shapes a user's scenario has and the bundled ones do not:

* :func:`~avrisk.testing.generated.k_region_problem` -- ``k`` half-space
  failure regions of unequal mass with orthogonal normals in ``d`` dimensions
  (several mechanisms, one rare).
* :func:`~avrisk.testing.generated.plateau_problem` -- ``f`` constant (a tie)
  on 90% to 99.99% of ``P0`` and continuous elsewhere, as a capped
  time-to-collision is when nothing closes.
* :func:`~avrisk.testing.generated.decoy_problem` -- a common mechanism of
  low ``f`` that never ends in the event beside a rare one that does (a near
  miss beside the crash).
* :func:`~avrisk.testing.generated.beta_product_problem`,
  :func:`~avrisk.testing.generated.beta_pair_product_problem` and
  :func:`~avrisk.testing.problems.beta_sum_problem` -- blocks of the engine's
  :class:`~avrisk.rare.ScaledBeta` family.
* :func:`~avrisk.testing.reliability.reliability_problem` -- the
  structural-reliability problems of the
  ``otbenchmark`` package (OpenTURNS), mapped to standard-normal space by
  their input distributions' iso-probabilistic transforms: the problem is
  ``u ~ N(0, I_D)``, ``f(u) = g(T^-1(u))``, ``gamma = 0``.

Credit and licence: the reliability problems are those collected in the
"Reliability problems" repository of Rozsas and Slobbe (TNO, 2019) and
packaged by ``otbenchmark`` (Baudin, Fekhari and others, LGPL-3.0). Their
limit-state formulas and input distributions are re-implemented here from the
published definitions (no code of ``otbenchmark`` is copied); ``otbenchmark``
itself pins ``numpy<2`` and so is not a dependency. Its listed reference
probabilities are not used: each reference here is computed afresh (closed
form, one-dimensional quadrature, or conditional Monte Carlo), and several
differ from the listed ones by 0.75% to 6.7%.

:func:`suite_problem` builds any problem by name (a generated family takes
its parameters from the name, e.g. ``kregions_k5_d50_p1e-06``), and
:data:`SUITE` lists the names the benchmark runs by default
(``benchmarks/exact_suite.py``).
"""

from __future__ import annotations

import re
from collections.abc import Callable

from avrisk.testing.generated import (
    beta_pair_product_problem,
    beta_product_problem,
    decoy_problem,
    k_region_problem,
    plateau_problem,
)
from avrisk.testing.problems import AnalyticProblem, beta_sum_problem
from avrisk.testing.reliability import RELIABILITY_PROBLEMS, reliability_problem

__all__ = ["SUITE", "suite_problem"]

_PATTERNS: list[tuple[str, Callable[..., AnalyticProblem]]] = [
    (
        r"kregions_k(?P<k>\d+)_d(?P<dim>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, dim, p: k_region_problem(int(k), int(dim), float(p)),
    ),
    (
        r"plateau_(?P<kind>self|gate)_m(?P<share>[0-9.]+)_d(?P<dim>\d+)"
        r"_p(?P<p>[0-9.e+-]+)",
        lambda kind, share, dim, p: plateau_problem(
            float(share), float(p), int(dim), kind
        ),
    ),
    (
        r"decoy_s(?P<share>[0-9.]+)_d(?P<dim>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda share, dim, p: decoy_problem(float(share), float(p), int(dim)),
    ),
    (
        r"beta_product_k(?P<k>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, p: beta_product_problem(int(k), float(p)),
    ),
    (
        r"beta_pair_product_p(?P<p>[0-9.e+-]+)",
        lambda p: beta_pair_product_problem(float(p)),
    ),
    (
        r"beta_sum_k(?P<k>\d+)_p(?P<p>[0-9.e+-]+)",
        lambda k, p: _beta_sum(int(k), float(p)),
    ),
]


def _beta_sum(k: int, p: float) -> AnalyticProblem:
    problem = beta_sum_problem(k, p)
    return AnalyticProblem(
        f"beta_sum_k{k}_p{p:.0e}",
        problem.base,
        problem.f,
        problem.gamma,
        problem.p_exact,
        reference="closed form over the simplex (beta_sum_cdf)",
    )


def suite_problem(name: str) -> AnalyticProblem:
    """The problem called ``name`` (a :data:`SUITE` name or a family's pattern).

    Raises
    ------
    KeyError
        If no problem or family matches (the message lists the patterns).
    """
    if name in RELIABILITY_PROBLEMS or name == "four-branch":
        return reliability_problem(name)
    for pattern, build in _PATTERNS:
        match = re.fullmatch(pattern, name)
        if match:
            return build(**match.groupdict())
    raise KeyError(
        f"no problem {name!r}: one of {sorted(RELIABILITY_PROBLEMS)}, four-branch, "
        f"or a family: {', '.join(p for p, _ in _PATTERNS)}"
    )


#: The problems the benchmark runs by default: a few points of each family
#: and every reliability problem that is rare (RP55, p = 0.56, is left out).
SUITE: tuple[str, ...] = (
    "kregions_k1_d2_p1e-03",
    "kregions_k2_d20_p1e-05",
    "kregions_k2_d100_p1e-08",
    "kregions_k5_d50_p1e-06",
    "kregions_k10_d200_p1e-09",
    "kregions_k3_d1000_p1e-06",
    "plateau_self_m0.9_d10_p1e-06",
    "plateau_self_m0.99_d10_p1e-06",
    "plateau_self_m0.9999_d10_p1e-06",
    "plateau_gate_m0.9999_d10_p1e-06",
    "decoy_s0.03_d10_p1e-06",
    "beta_sum_k6_p1e-06",
    "beta_product_k4_p1e-06",
    "beta_pair_product_p1e-06",
    *RELIABILITY_PROBLEMS,
    "four-branch",
)
