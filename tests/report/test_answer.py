import pytest

from avrisk.rare.trust import Trust
from avrisk.report.answer import headline, run_trust, search_remark, threshold_trust


def summary(method="ce", p=1e-4, ci=(0.5e-4, 1.5e-4), quantiles=(), **main):
    """A run's summary at gamma 0.1 s; ``quantiles``: its search's, per iteration."""
    g = {"gamma": 0.1, "p": p, "ci": list(ci), "n_hits": 50, "ess": 40.0}
    g.update(main)
    est = {"gamma": 0.1, "p": p, "ci": list(ci), "n_evals": 1000, "by_gamma": [g]}
    est["history"] = [{"iteration": k, "quantile": q} for k, q in enumerate(quantiles)]
    return {"method": method, "estimate": est}


def test_a_run_s_trust_speaks_of_its_rollouts_and_min_ttc():
    no_hit = summary("naive", n_hits=0, ess=0.0)
    assert run_trust(no_hit).reasons == (
        "no rollout reached min TTC <= 0.1 s: the interval is a bound only",
    )
    failed = summary("naive", n_hits=50, ess=50.0, n_failed=3)
    assert "3 rollouts failed to evaluate" in str(run_trust(failed))


def test_the_headline_is_the_trusted_run_with_the_narrowest_interval():
    ce = summary(ci=(0.9e-4, 1.1e-4), pareto_k=0.9)  # narrowest, but caution
    naive = summary("naive", ci=(0.2e-4, 3e-4))
    reference = summary("naive", p=1.2e-4, ci=(1e-4, 1.4e-4))
    runs = [("ce", ce), ("naive", naive), ("reference", reference)]
    lead = headline(runs, horizon_s=10.0)
    assert lead.label == "reference" and lead.trust.ok and lead.chosen_from == 3
    # when no run is trusted, the run under test, with its reasons
    lead = headline([("ce", ce)], horizon_s=10.0)
    assert lead.label == "ce" and not lead.trust.ok
    assert not run_trust(ce).ok


def test_the_headline_states_its_time_base_and_per_hour_approximation():
    lead = headline([("cross-entropy", summary(p=2e-4))], horizon_s=10.0)
    assert lead.sentence() == (
        "P(min TTC <= 0.1 s) per 10-s rollout from P0 = 0.0002 (95% CI 5e-05 to "
        "0.00015), method cross-entropy, 1,000 rollouts; trust: ok"
    )
    assert lead.per_hour == pytest.approx(2e-4 * 360)
    assert "about 0.072 events" in lead.time_base()
    assert "approximation" in lead.time_base()
    doc = lead.to_dict()
    assert doc["trust"] == "ok" and doc["per_hour_approx"] == pytest.approx(0.072)
    unknown = headline([("ce", summary())], horizon_s=None)
    assert unknown.event == "P(min TTC <= 0.1 s) per rollout from P0"
    assert unknown.per_hour is None and unknown.to_dict()["per_hour_approx"] is None


def test_a_search_short_of_gamma_is_said_first_beside_the_sample_s_doubts():
    stalled = summary(quantiles=(1.9, 1.2, 0.8), pareto_k=0.9)
    trust = run_trust(stalled)
    assert trust.reasons[0].startswith(
        "the search did not reach min TTC <= 0.1 s: its lowest rho-quantile of min "
        "TTC in 3 iterations was 0.8 s, so its proposal aims at a less rare event"
    )
    assert "Pareto k = 0.90" in trust.reasons[1]  # the final stage's own, after
    assert len(trust.reasons) == 2
    # short of gamma, but its final sample's weights raise no doubt: their
    # interval stands (importance sampling from a proposal aimed higher)
    assert run_trust(summary(quantiles=(1.9, 1.2, 0.8), pareto_k=0.4)).ok
    # reached gamma and drifted back: not settled, a doubt of its own
    drifted = run_trust(summary(quantiles=(1.9, 0.05, 0.8), pareto_k=0.4))
    assert len(drifted.reasons) == 1
    assert drifted.reasons[0].startswith(
        "the search reached min TTC <= 0.1 s after 2 of its 3 iterations but"
    )
    converged = summary(quantiles=(1.9, 0.05, 0.02))
    assert run_trust(converged).ok
    # how the search ended is remarked on where the trust does not say it
    assert search_remark(stalled, trust) is None
    healthy = summary(quantiles=(1.9, 1.2, 0.8), pareto_k=0.4)
    assert search_remark(healthy, run_trust(healthy)).startswith(
        "the search did not reach min TTC <= 0.1 s"
    )
    assert search_remark(converged, run_trust(converged)).endswith("(converged)")
    assert search_remark(summary("naive"), Trust()) is None  # no search
    # each threshold is judged on its own: the same search reached 1 s
    at_one = {"gamma": 1.0, "n_hits": 80, "ess": 60.0}
    assert threshold_trust(summary(quantiles=(1.9, 1.2, 0.8)), at_one).ok
    # naive Monte Carlo searches nothing
    assert run_trust(summary("naive", quantiles=())).ok
    lead = headline([("cross-entropy", stalled)], horizon_s=10.0)
    assert lead.to_dict()["reasons"][0].startswith("the search did not reach")
