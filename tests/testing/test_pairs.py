"""Pairs of half-space problems with exact p_A, p_B and p_AB (avrisk.testing.pairs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from avrisk.testing.pairs import PAIR_SUITE, pair_problem


def test_the_pairs_exact_probabilities_agree_with_sampling():
    pair = pair_problem("overlap_r0.3_p1e-02_d3")
    x = np.random.default_rng(0).standard_normal((400_000, 3))
    fails = pair.f(x) <= 0.0
    n = len(x)
    for got, p in (
        (fails[:, 0].mean(), pair.p_a),
        (fails[:, 1].mean(), pair.p_b),
        ((fails[:, 0] & fails[:, 1]).mean(), pair.p_ab),
    ):
        assert abs(got - p) < 4 * math.sqrt(p / n)
    assert pair.discordant_share == pytest.approx(0.3)
    assert pair.p_a == pytest.approx(1e-2) and pair.ratio == pytest.approx(1.0)


@pytest.mark.parametrize("name", PAIR_SUITE)
def test_the_suite_names_build_the_pairs_they_name(name):
    pair = pair_problem(name)
    assert pair.name == name
    assert 0.0 <= pair.p_ab <= min(pair.p_a, pair.p_b)


def test_disjoint_and_nested_pairs_have_the_extreme_overlaps():
    assert pair_problem("disjoint_ratio2_p1e-04_d3").p_ab == 0.0
    nested = pair_problem("nested_r0.5_p1e-04_d3")
    assert nested.p_ab == pytest.approx(nested.p_b, rel=1e-12)
    assert nested.discordant_share == pytest.approx(0.5)


def test_an_unknown_name_is_refused():
    with pytest.raises(ValueError, match="no pair problem"):
        pair_problem("nested_ratio2_p1e-04_d3")
