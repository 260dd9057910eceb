"""The engine's one trust rule: diagnostics, search, and each estimator's doubts."""

import math

import numpy as np
from scipy import stats

from avrisk.rare import (
    Estimate,
    FixedCovNormal,
    GammaEstimate,
    splitting_is,
    subset_simulation,
)
from avrisk.rare.estimator import estimator_class
from avrisk.rare.splitting_genealogy import interval_quantile
from avrisk.rare.splitting_replicates import (
    estimates_disagree,
    exhausted_doubts,
    replicates_disagree,
)
from avrisk.rare.trust import GENERIC, Trust, Wording, estimate_trust, trust_at

GOOD = {"gamma": 0.0, "n_hits": 50, "ess": 40.0, "pareto_k": 0.4}


def test_the_estimate_s_own_diagnostics_decide_in_the_problem_s_words():
    assert trust_at(GOOD, weighted=True) == Trust()
    assert str(trust_at(GOOD, weighted=True)) == "ok"
    heavy = trust_at({**GOOD, "pareto_k": 0.9}, weighted=True)
    assert not heavy.ok and "Pareto k = 0.90 > 0.7" in str(heavy)
    assert "effective hits" in str(trust_at({**GOOD, "ess": 3.0}, weighted=True))
    assert trust_at({**GOOD, "n_hits": 0}, weighted=True).reasons == (
        "no sample reached f <= 0: the interval is a bound only",
    )
    ttc = Wording("min TTC", " s", "rollout")
    assert "no rollout reached min TTC <= 0 s" in str(
        trust_at({**GOOD, "n_hits": 0}, True, ttc)
    )
    # naive Monte Carlo: its hits decide, weights have no tail to speak of
    assert trust_at({"gamma": 0.0, "n_hits": 50, "ess": 50.0}, weighted=False).ok
    few = trust_at({"gamma": 0.0, "n_hits": 4, "ess": 4.0}, weighted=False)
    assert str(few) == "caution (only 4 hits: relative standard error about 50%)"
    failed = trust_at({**GOOD, "n_failed": 3}, weighted=True, wording=GENERIC)
    assert failed.reasons == (
        "3 samples failed to evaluate: p counts them safe, the interval reaches "
        "counting them dangerous",
    )
    # an older summary without pareto_k is read on its effective hits
    assert trust_at({**GOOD, "pareto_k": None}, True).ok


def trust_of(method, estimate):
    as_dict = estimate.to_dict()
    main = next(g for g in as_dict["by_gamma"] if g["gamma"] == estimate.gamma)
    return estimate_trust(estimator_class(method), as_dict, main)


def replicate(p, stderr, n_hits=100, dof=math.inf):
    """A replicate's estimate at gamma 0 (its interval log-normal).

    With finite ``dof``, the interval takes Student's t at ``dof`` degrees
    of freedom, as a family tree's of few families does.
    """
    half = interval_quantile(dof) * np.sqrt(np.log1p((stderr / p) ** 2)) if p else 0
    ci = (p * np.exp(-half), p * np.exp(half)) if p else (0.0, stderr)
    g = GammaEstimate(0.0, p, stderr, ci, n_hits, float(n_hits), 1000)
    details = {"dof": [None if math.isinf(dof) else dof]}
    return Estimate("subset_simulation", 0.0, {0.0: g}, 1000, details=details)


def test_replicates_disagree_beyond_their_errors_only():
    assert not replicates_disagree([replicate(1e-6, 3e-7), replicate(2e-6, 6e-7)])
    # log p 2.3 apart, standard error of the difference about 0.42
    assert replicates_disagree([replicate(1e-6, 3e-7), replicate(1e-5, 3e-6)])
    # a bound below the other's interval, and one that is not
    assert replicates_disagree([replicate(1e-5, 2e-6), replicate(0.0, 1e-6, 0)])
    assert not replicates_disagree([replicate(1e-6, 2e-7), replicate(0.0, 1e-5, 0)])


def test_replicates_disagree_only_beyond_the_errors_their_intervals_state():
    # log p 3.0 apart, each with Var(log p) = log(1 + 0.5^2) = 0.223: 4.5 normal
    # standard errors of the difference, beyond DISAGREEMENT_Z = 3
    normal = [replicate(1e-6, 5e-7), replicate(20e-6, 1e-5)]
    assert replicates_disagree(normal)
    # the same spread read off two families (t at 1 degree of freedom, 12.7
    # against 1.96): 0.7 of such errors apart, well inside the intervals
    few = [replicate(1e-6, 5e-7, dof=1.0), replicate(20e-6, 1e-5, dof=1.0)]
    assert not replicates_disagree(few)
    assert few[0].ci[1] > few[1].p and few[1].ci[0] < few[0].p


def test_replicates_that_disagree_are_recorded_not_a_caution_of_their_own():
    f = lambda x: 4.0 - x[:, 0]  # noqa: E731
    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    est = splitting_is(f, base, 0.0, n_particles=1000, n_final=4000, seed=0)
    assert not est.details["replicates_disagree"]
    assert trust_of("splitting_is", est).ok
    # the proposal holds what either replicate found: an importance-sampling
    # estimate that one replicate bears out is trusted
    as_dict = est.to_dict()
    as_dict["details"]["replicates_disagree"] = True
    as_dict["details"]["replicates"][1] = {"p": est.p / 100, "ci": [0, est.p / 50]}
    main = as_dict["by_gamma"][0]
    assert estimate_trust(estimator_class("splitting_is"), as_dict, main).ok


def test_a_level_held_by_a_handful_of_particles_makes_splitting_say_caution():
    t, b = stats.norm.isf(1e-3), stats.norm.isf(1e-2)

    def f(x):  # 99.9% of P0 ties at 5: one in 1,000 draws below it
        return np.where(x[:, 1] >= t, np.minimum(5.0, b - x[:, 0]), 5.0)

    base = FixedCovNormal(np.zeros(2), cov=np.eye(2))
    est = subset_simulation(
        f, base, 0.0, n_particles=1000, seed=1, plateau_draws=2, replicates=1
    )
    assert est.details["survivors"][0] == 2  # one replicate: its first level
    trust = trust_of("splitting", est)
    assert "held only 2 particles" in str(trust)


def test_importance_sampling_far_from_its_own_levels_says_caution():
    sampled = {"gamma": 0.0, "p": 1e-7, "stderr": 1e-8, "ci": [8e-8, 1.2e-7]}
    levels = {"p": 1e-6, "ci": [5e-7, 2e-6]}
    assert estimates_disagree(sampled, levels)
    assert not estimates_disagree(sampled | {"p": 8e-7, "stderr": 8e-8}, levels)
    as_dict = {
        "gamma": 0.0,
        "by_gamma": [{**sampled, "n_hits": 500, "ess": 400.0, "pareto_k": 0.2}],
        "details": {"replicates": [levels, levels | {"p": 2e-6, "ci": [1e-6, 4e-6]}]},
    }
    trust = estimate_trust(
        estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
    )
    assert "importance sampling found p = 1e-07 but the levels" in str(trust)
    # above every replicate the levels lost part of the event, not the proposal
    above = {**sampled, "p": 1e-5, "stderr": 1e-6, "ci": [8e-6, 1.2e-5]}
    as_dict["by_gamma"] = [{**above, "n_hits": 500, "ess": 400.0, "pareto_k": 0.2}]
    assert estimates_disagree(above, levels)
    trust = estimate_trust(
        estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
    )
    assert trust.ok
    # one replicate that bears it out is enough
    as_dict["details"]["replicates"][1] = {"p": 1.1e-7, "ci": [6e-8, 2e-7]}
    assert estimate_trust(
        estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
    ).ok


def test_levels_that_answer_far_from_their_own_importance_sample_say_caution():
    levels = {"gamma": 0.0, "p": 1e-6, "stderr": 2e-7, "ci": [6.7e-7, 1.5e-6]}
    sampled = {"p": 1e-7, "stderr": 1e-8, "ci": [8e-8, 1.2e-7], "n_hits": 500}
    sampled |= {"ess": 400.0, "pareto_k": 0.2}
    as_dict = {
        "gamma": 0.0,
        "by_gamma": [{**levels, "n_hits": 300, "ess": 300.0, "pareto_k": None}],
        "details": {
            "answer": "splitting",
            "replicates": [levels, levels],
            "survivors": [[200, 200, 150], [200, 200, 150]],
            "importance_sampling": {"0.0": sampled},
        },
    }

    def trust():
        return estimate_trust(
            estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
        )

    assert "the levels found p = 1e-06 but importance sampling" in str(trust())
    # below them with a heavy tail: still a doubt; with a handful of
    # effective hits: none (such a sample falls low as a rule)
    as_dict["details"]["importance_sampling"]["0.0"] = sampled | {"pareto_k": 0.9}
    assert "the levels found p = 1e-06 but importance sampling" in str(trust())
    as_dict["details"]["importance_sampling"]["0.0"] = sampled | {"ess": 4.0}
    assert trust().ok
    # above them it belies them, whatever its weights
    above = {"p": 1e-5, "stderr": 1e-6, "ci": [8e-6, 1.2e-5], "ess": 4.0}
    as_dict["details"]["importance_sampling"]["0.0"] = sampled | above
    assert "importance sampling from their particles 1e-05" in str(trust())
    # a sample that bears the levels out: no doubt
    as_dict["details"]["importance_sampling"]["0.0"] = sampled | {"p": 9e-7}
    assert trust().ok
    # replicates whose products disagree: subset simulation's own doubt
    as_dict["details"]["replicates_disagree"] = True
    assert "the replicates of the search found p = 1e-06, 1e-06" in str(trust())
    as_dict["details"]["replicates_disagree"] = False
    # a level of the levels held by a handful of particles: their own doubt
    as_dict["details"]["survivors"][1] = [200, 3, 150]
    assert "held only 3 particles" in str(trust())


def test_importance_sampling_below_the_pooled_levels_says_caution():
    # neither replicate alone is far enough from the sample (their intervals
    # are wide), but their pool is: the run's own levels' estimate
    sampled = {"gamma": 0.0, "p": 1.2e-7, "stderr": 1.5e-8, "ci": [9e-8, 1.5e-7]}
    own = [
        {"p": 2.5e-7, "ci": [1.05e-7, 6.1e-7]},
        {"p": 3.8e-7, "ci": [2.05e-7, 7.1e-7]},
    ]
    assert not all(estimates_disagree(sampled, r) for r in own)
    pooled = {"p": 3.2e-7, "ci": [1.9e-7, 5.4e-7]}
    assert estimates_disagree(sampled, pooled)
    as_dict = {
        "gamma": 0.0,
        "by_gamma": [{**sampled, "n_hits": 900, "ess": 65.0, "pareto_k": 0.66}],
        "details": {
            "replicates": own,
            "replicates_disagree": False,
            "splitting": {"0.0": pooled},
        },
    }
    trust = estimate_trust(
        estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
    )
    assert "the levels of the same run 3.2e-07 (replicates 2.5e-07" in str(trust)
    # a replicate whose own estimate is at or below the sample's bears it out
    borne = {**as_dict, "details": {**as_dict["details"], "replicates": [own[1]]}}
    borne["details"]["replicates"].append({"p": 1.1e-7, "ci": [4e-8, 3e-7]})
    assert estimate_trust(
        estimator_class("splitting_is"), borne, borne["by_gamma"][0]
    ).ok
    # replicates that disagree with each other are no fair pool: one that
    # bears the sample out is enough
    as_dict["details"]["replicates_disagree"] = True
    assert estimate_trust(
        estimator_class("splitting_is"), as_dict, as_dict["by_gamma"][0]
    ).ok


def test_a_run_out_of_levels_is_doubted_unless_its_mechanism_cannot_move_the_answer():
    # one replicate reached gamma, the other ran out of levels at f <= 0.5,
    # where its own sets put P0(f <= 0.5) below 1.2e-11
    details = {
        "replicates": [{"p": 1e-6, "ci": [5e-7, 2e-6], "n_hits": 300}],
        "replicates_exhausted": 1,
        "exhausted_mass": [{"level": 0.5, "p": 1.7e-12, "upper": 1.2e-11}],
    }
    sampled = {"p": 1e-6, "stderr": 5e-8, "n_hits": 4000}
    # an importance sample's answer with an error far above that mass: no doubt
    assert exhausted_doubts(details, sampled) == ()
    # the same run out of levels at a mass the answer's error does not cover
    deep = {**details, "exhausted_mass": [{"level": 0.5, "p": 4e-8, "upper": 9e-8}]}
    (doubt,) = exhausted_doubts(deep, sampled)
    assert doubt.startswith("1 of the 2 replicates of the search did not reach gamma")
    # the levels' answer (no sample), an answer with no hit, or a record that
    # does not say the mass: the doubt stands
    assert exhausted_doubts(details) == (doubt,)
    assert exhausted_doubts(details, {**sampled, "n_hits": 0}) == (doubt,)
    old = {k: v for k, v in details.items() if k != "exhausted_mass"}
    assert exhausted_doubts(old, sampled) == (doubt,)
