"""The audit of a cross-entropy proposal by an independent subset simulation."""

import warnings

import numpy as np
import pytest

from avrisk.rare.black_box import estimate
from avrisk.rare.estimator import estimator_class, get_estimator
from avrisk.rare.families import FixedCovNormal
from avrisk.rare.proposal_audit import audit_bound, audit_doubts
from avrisk.rare.trust import estimate_trust
from avrisk.testing import gaussian_linear_problem
from avrisk.testing.suite import suite_problem

#: Two half-space regions in d = 20, masses 2:1 (exact p = 1e-5): a CE search
#: finds one of them.
TWO_REGIONS = suite_problem("kregions_k2_d20_p1e-05")
SMALL = dict(n_iter=10, n_per_iter=2000, n_final=20_000)


def trust(method, est):
    summary = est.to_dict()
    main = summary["by_gamma"][0]
    return estimate_trust(estimator_class(method), summary, main)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_region_the_search_missed_makes_ce_say_caution(seed):
    p = TWO_REGIONS
    est = estimate("ce", p.f, p.base, p.gamma, seed=seed, **SMALL)
    assert est.ci[1] < p.p_exact  # CE found one region: its interval misses p
    audit = est.details["audit"]
    assert audit["doubt"] and audit["n_uncovered"] > 0.2 * audit["n_at_gamma"]
    reasons = trust("ce", est).reasons
    assert any("independent search" in r for r in reasons)
    # the reports show it as a table of its own, after the search's
    search, table = estimator_class("ce").diagnostics(est.to_dict())
    (row,) = table.rows
    assert row[0] == audit["particles"] and row[-1] == "caution"
    # ... and the estimate is the one the run gives without the audit
    alone = estimate("ce", p.f, p.base, p.gamma, seed=seed, audit_particles=0, **SMALL)
    assert (alone.p, alone.stderr) == (est.p, est.stderr) and "audit" not in (
        alone.details or {}
    )
    assert est.n_evals == alone.n_evals + audit["n_calls"]
    assert trust("ce", alone).ok  # what the label said before the audit


@pytest.mark.parametrize("method", ["ce", "mixture"])
def test_a_proposal_that_covers_the_event_passes_the_audit(method):
    p = gaussian_linear_problem(10, p=1e-6)
    est = estimate(method, p.f, p.base, p.gamma, seed=3, **SMALL)
    audit = est.details["audit"]
    assert audit["reached"] and audit["n_at_gamma"] >= 40
    assert audit["n_uncovered"] == 0 and not audit["doubt"]
    assert audit["particles"] == 400  # one per 50 final draws
    assert audit["n_calls"] <= audit_bound(400)
    # the audit's own estimate is an independent estimate of p
    assert audit["ci"][0] < p.p_exact < audit["ci"][1]
    assert trust(method, est).ok


def test_mixture_ce_keeps_both_regions_and_passes_where_ce_does_not():
    p = TWO_REGIONS
    est = estimate("mixture", p.f, p.base, p.gamma, seed=0, **SMALL)
    assert est.ci[0] < p.p_exact < est.ci[1]
    assert not est.details["audit"]["doubt"]


def test_an_unreachable_event_gives_an_audit_with_nothing_to_say():
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no hit: the bound's own warning
        est = estimate("ce", lambda x: np.ones(len(x)), base, 0.0, seed=0, **SMALL)
    audit = est.details["audit"]
    assert est.p == 0 and audit["n_at_gamma"] == 0 and not audit["doubt"]
    assert not any("independent search" in r for r in trust("ce", est).reasons)


def test_the_doubt_is_for_the_runs_own_threshold_only():
    summary = {
        "gamma": 0.0,
        "details": {
            "audit": {
                "doubt": True,
                "n_uncovered": 50,
                "n_at_gamma": 100,
                "missed_low": 1e-6,
            }
        },
    }
    (reason,) = audit_doubts(summary, 0.0)
    assert "50% of its 100 particles" in reason and "1e-06" in reason
    assert audit_doubts(summary, 0.5) == ()
    assert audit_doubts({"gamma": 0.0}, 0.0) == ()


def test_no_audit_costs_nothing_and_a_too_small_one_is_refused():
    assert audit_bound(0) == 0
    assert audit_bound(1000) == 12 * 1000
    with pytest.raises(ValueError, match="audit_particles: Value error, must be 0"):
        get_estimator("ce", audit_particles=5)
