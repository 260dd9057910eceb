"""The A/B comparison of two egos (avrisk.compare_egos): run directory, resume, gate."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

import avrisk
from avrisk.api import events
from avrisk.api.ab import PAIR_UNITS, final_sample
from avrisk.api.result import samples_directory
from avrisk.api.runs import scenario_spec
from avrisk.assembly import base_distribution
from avrisk.pipeline import RunDirectoryError
from avrisk.rare.parallel import EVALUATED_BY
from avrisk.scenario import ScenarioSpec

#: A short, not-rare comparison: a few hundred rollout pairs.
SMALL = dict(gamma=2.0, n_particles=100, n_final=200, batch_size=200, failures=0)
HOLD = {"policy": "tests.user_components:HoldSpeedEgo", "params": {"speed": 25}}


def short_scenario():
    """highway_idm with 4 s rollouts."""
    data = scenario_spec("highway_idm").model_dump(mode="json")
    data["simulation"]["horizon"] = 4.0
    return data


def test_two_egos_are_compared_written_and_read_back(tmp_path):
    seen = []
    result = avrisk.compare_egos(
        short_scenario(),
        "idm_mobil",
        HOLD,
        out=tmp_path,
        progress=seen.append,
        **{**SMALL, "failures": 1},
    )
    kinds = [type(e) for e in seen]
    assert kinds[:3] == [events.Plan, events.RunOpened, events.RunStarted]
    est = result.paired
    for part in (est.a, est.b):
        assert part.ci[0] <= part.p <= part.ci[1] and part.n_hits > 0
    assert est.difference.value == pytest.approx(est.b.p - est.a.p)
    # the proposal read back from the summary gives the recorded densities,
    # so its components serve as control variates (here one component, at P0
    # as this event is not rare: a constant control, and none fitted)
    spec = ScenarioSpec.model_validate(short_scenario())
    run_dir = samples_directory(tmp_path, spec, outputs=PAIR_UNITS)
    proposal = run_dir.summary()["estimate"]["proposal"]
    sample = final_sample(run_dir, base_distribution(spec), proposal)
    assert sample.controls.shape == (sample.log_w.size, 1)
    assert np.allclose(sample.controls, 0.0)
    assert final_sample(run_dir).controls.shape == (sample.log_w.size, 0)
    assert result.verdict.outcome in ("pass", "fail", "inconclusive")
    assert result.line().startswith(result.verdict.outcome.upper())
    document = json.loads((tmp_path / "ab.json").read_text())
    assert document["schema"] == "avrisk.ab/1" and document["ego_b"] == HOLD
    assert document == json.loads(json.dumps(result.document()))
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["ego_a"]["policy"] == "idm_mobil" and config["ego_b"] == HOLD
    # the discordant rollouts, the most realistic first, and their share of p
    regressions = result.discordant["regressions"]
    assert len(regressions) == est.regressions.n_hits > 0
    assert all(r["f_b"] <= 2.0 < (r["f_a"] or np.inf) for r in regressions)
    ranks = [r["percentile"] for r in regressions]
    assert ranks == sorted(ranks, reverse=True)
    html = result.report.read_text()
    assert html.index("regressions: B fails, A does not") < html.index("fixes: A fails")
    # the first regression: both egos on the same draw, in one GIF, in step
    assert (tmp_path / "ab" / "regressions1.gif").is_file()
    assert 'src="ab/regressions1.gif"' in html
    again = []
    same = avrisk.compare_egos(
        short_scenario(),
        "idm_mobil",
        HOLD,
        out=tmp_path,
        progress=again.append,
        **{**SMALL, "failures": 1},
    )
    assert not any(isinstance(e, events.RunStarted) for e in again)
    assert same.document() == result.document()
    result.report.unlink()  # written again, as compare_egos wrote it
    assert avrisk.write_report(tmp_path) == result.report
    assert result.report.read_text() == html


def test_a_resume_with_another_ego_is_refused(tmp_path):
    avrisk.compare_egos(short_scenario(), "idm_mobil", HOLD, out=tmp_path, **SMALL)
    other = {**HOLD, "params": {"speed": 20}}
    with pytest.raises(RunDirectoryError):
        avrisk.compare_egos(short_scenario(), "idm_mobil", other, out=tmp_path, **SMALL)


def test_two_local_workers_give_the_in_process_comparison_bit_for_bit(tmp_path):
    runs = {}
    for name, where in {"here": {}, "workers": {"workers": 2}}.items():
        out = tmp_path / name
        result = avrisk.compare_egos(
            short_scenario(), "idm_mobil", HOLD, out=out, **SMALL, **where
        )
        runs[name] = result, pq.read_table(out / "samples.parquet")
    (here, here_table), (there, there_table) = runs["here"], runs["workers"]
    assert here.paired.regressions.n_hits > 0  # the egos differ somewhere
    assert (there.paired.a.p, there.paired.b.p) == (here.paired.a.p, here.paired.b.p)
    without_time = [r.paired.to_dict() for r in (here, there)]
    for paired in without_time:
        paired["union"].pop("wall_time_s")
    assert without_time[0] == without_time[1]
    assert there.verdict == here.verdict
    assert there.discordant == here.discordant
    assert EVALUATED_BY not in here_table.column_names
    assert there_table.drop([EVALUATED_BY]).equals(here_table)
    labels = there_table[EVALUATED_BY].to_pylist()
    assert all(s.startswith("processes ") and s.endswith(" cpu") for s in labels)


def test_the_same_ego_twice_has_no_discordant_pair(tmp_path):
    result = avrisk.compare_egos(
        short_scenario(), "idm_mobil", "idm_mobil", out=tmp_path, **SMALL
    )
    est = result.paired
    assert est.regressions.n_hits == est.fixes.n_hits == 0
    assert est.a.p == est.b.p
    lo, hi = est.difference.ci
    assert lo < 0.0 < hi
    assert result.verdict.outcome == "inconclusive"


def test_the_pairs_share_x_and_seeds(tmp_path):
    from avrisk.assembly import SimulationObjective, base_distribution
    from avrisk.assembly.paired import PairedObjective

    spec = avrisk.api._spec(short_scenario(), None)
    pair = PairedObjective(SimulationObjective(spec), SimulationObjective(spec))
    x = base_distribution(spec).sample(8, np.random.default_rng(0))
    out = pair(x, np.arange(8, dtype=np.int64))
    assert out["f"].shape == (8, 2)
    np.testing.assert_array_equal(out["f"][:, 0], out["f"][:, 1])
    np.testing.assert_array_equal(out["crash_a"], out["crash_b"])
