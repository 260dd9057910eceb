"""``avrisk ab``: the gate's line, exit codes, --json, resume, two external AVs."""

import json
import socket
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from PIL import Image
from typer.testing import CliRunner

from avrisk.cli.app import app
from tests.interrupts import ctrl_c_at_chunk
from tests.scenario_files import shortened_scenario

ROOT = Path(__file__).resolve().parents[2]

SMALL = ("--gamma", 2.0, "--set", "n_particles=100", "--n-final", 200, "--failures", 0)
HOLD_FAST = '{policy: "tests.user_components:HoldSpeedEgo", params: {speed: 30}}'


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """highway_idm with 3 s rollouts."""
    return shortened_scenario(tmp_path_factory.mktemp("scenario"), 3.0)


def test_a_worse_ego_fails_the_gate_with_exit_code_1(short, tmp_path):
    out = tmp_path / "ab"
    result = invoke("ab", short, "--ego-b", HOLD_FAST, "--out", out, *SMALL)
    document = json.loads((out / "ab.json").read_text())
    assert result.exit_code == 1, result.output
    assert document["verdict"]["outcome"] == "fail"
    assert result.stdout.strip() == document["line"]
    assert document["line"].startswith("FAIL: p_B/p_A = ")
    assert document["ego_a"]["policy"] == "idm_mobil"  # the scenario's own
    # the reverse comparison passes at the same margin
    back = invoke(
        "ab", short, "--ego-a", HOLD_FAST, "--ego-b", "idm_mobil",
        "--out", tmp_path / "ba", *SMALL, "--json",
    )  # fmt: skip
    assert back.exit_code == 0, back.output
    assert json.loads(back.stdout)["verdict"]["outcome"] == "pass"


def test_the_same_ego_is_inconclusive_with_exit_code_3_and_is_read_back(
    short, tmp_path
):
    out = tmp_path / "same"
    same = ("--ego-a", "idm_mobil", "--ego-b", "idm_mobil")  # default params both
    args = ("ab", short, *same, "--out", out, *SMALL, "--json")
    result = invoke(*args)
    assert result.exit_code == 3, result.output
    document = json.loads(result.stdout)
    assert document["verdict"]["outcome"] == "inconclusive"
    paired = document["paired"]
    assert paired["regressions"]["n_hits"] == paired["fixes"]["n_hits"] == 0
    low, high = paired["difference"]["ci"]
    assert low < 0 < high
    table = pq.read_table(out / "samples.parquet", columns=["f_a", "f_b"])
    assert table["f_a"].equals(table["f_b"])  # the same draws, the same rollouts
    again = invoke(*args)
    assert again.exit_code == 3 and json.loads(again.stdout) == document


def test_an_ego_that_is_not_a_mapping_is_one_line(short, tmp_path):
    result = invoke("ab", short, "--ego-b", "{speed: 3}", "--out", tmp_path / "x")
    assert result.exit_code == 2
    assert "--ego-b must hold a mapping with 'policy'" in result.output


def test_backend_options_reach_the_comparison(short, tmp_path):
    out = tmp_path / "ab"
    result = invoke("ab", short, "--ego-b", HOLD_FAST, "--out", out, *SMALL,
                    "--address", "10.0.0.1:6379")  # fmt: skip
    assert result.exit_code == 2
    message = " ".join(result.output.split()).replace("│", "")
    assert "--address joins a Ray cluster: add --backend ray" in message
    assert "Traceback" not in result.output and not out.exists()


def test_report_rebuilds_the_ab_report_as_ab_wrote_it(short, tmp_path, monkeypatch):
    out = tmp_path / "ab"
    made = invoke("ab", short, "--ego-b", HOLD_FAST, "--out", out, *SMALL[:-1], 1)
    assert made.exit_code == 1, made.output
    html, record = (out / "ab_report.html").read_text(), (out / "ab.json").read_text()
    assert 'src="ab/regressions1.gif"' in html  # A above B, in step
    (out / "ab_report.html").unlink()
    monkeypatch.setitem(sys.modules, "tests.user_components", None)  # B's code

    rebuilt = invoke("report", out)
    assert rebuilt.exit_code == 0, rebuilt.output
    assert rebuilt.stdout.strip() == json.loads(record)["line"]
    assert f"report: {out / 'ab_report.html'}" in " ".join(rebuilt.stderr.split())
    assert (out / "ab_report.html").read_text() == html
    assert (out / "ab.json").read_text() == record
    doc = json.loads(invoke("report", out, "--json").stdout)
    assert doc == json.loads(record)
    # an animation lost is made again for A (a registered ego), left out for B
    # (user code, which a run directory never makes avrisk import)
    with Image.open(out / "ab" / "regressions1.gif") as pair:
        pair_height, pair_frames = pair.size[1], pair.n_frames
    (out / "ab" / "regressions1.gif").unlink()
    assert invoke("report", out).exit_code == 0
    assert not (out / "ab" / "regressions1.gif").exists()
    with Image.open(out / "ab" / "regressions1_a.gif") as single:
        # A's panel above B's, the same steps: twice as high, as many frames
        assert pair_height > 1.8 * single.size[1] and pair_frames == single.n_frames
    assert (out / "ab" / "regressions1_a.gif").is_file()
    assert not (out / "ab" / "regressions1_b.gif").exists()
    html = (out / "ab_report.html").read_text()
    assert "ab/regressions1_a.gif" in html and "ab/regressions1_b.gif" not in html


def test_report_of_an_ab_directory_refuses_in_one_line(short, tmp_path):
    out = tmp_path / "ab"
    same = ("--ego-a", "idm_mobil", "--ego-b", "idm_mobil")
    assert invoke("ab", short, *same, "--out", out, *SMALL).exit_code == 3
    given = invoke("report", out, "--scenario", short)
    assert given.exit_code == 2
    assert "is an A/B comparison: its scenario is not given again" in given.output
    (out / "ab.json").write_text('{"schema": "avrisk.ab/1", "verdict": {}}')
    damaged = invoke("report", out)
    assert damaged.exit_code == 2 and "Traceback" not in damaged.output
    assert "not an A/B record (verdict.max_ratio: Field required)" in " ".join(
        damaged.output.split()
    )
    (out / "ab.json").unlink()
    missing = invoke("report", out)
    assert missing.exit_code == 2
    assert "ab.json: missing; rerun the avrisk ab command" in " ".join(
        missing.output.split()
    )
    assert not (out / "report.html").exists()


def free_address():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def test_two_external_avs_are_compared_on_the_same_draws(short, tmp_path):
    pytest.importorskip("zmq")
    from tests.cli.ego_servers import FaultyServer, LateBrakingController, in_thread

    egos = [free_address(), free_address()]
    servers = [
        FaultyServer("none"),
        FaultyServer("none", controller=LateBrakingController()),
    ]

    def ego(address):
        return f'{{policy: external, params: {{address: "{address}"}}}}'

    with in_thread(servers[0], egos[0]), in_thread(servers[1], egos[1]):
        result = invoke(
            "ab", short, "--ego-a", ego(egos[0]), "--ego-b", ego(egos[1]),
            "--out", tmp_path / "ab", *SMALL, "--json",
        )  # fmt: skip
    assert result.exit_code in (0, 1, 3), result.output
    document = json.loads(result.stdout)
    assert document["ego_b"]["params"]["address"] == egos[1]
    table = pq.read_table(tmp_path / "ab" / "samples.parquet")
    assert (table["status"].to_numpy() == 0).all()
    # a later brake changes some rollouts, not all: the draws are shared
    f_a, f_b = table["f_a"].to_numpy(), table["f_b"].to_numpy()
    assert 0 < (f_a != f_b).sum() < len(f_a)


def test_the_bundled_lidar_pair_runs_on_the_same_draws(tmp_path):
    pair = ROOT / "examples" / "ab_lidar"
    short = shortened_scenario(tmp_path, 2.0, scenario="highway_default")
    result = invoke(
        "ab", short, "--ego-a", pair / "lidar_ego.yaml",
        "--ego-b", pair / "lidar_ego_degraded.yaml",
        "--out", tmp_path / "ab", *SMALL, "--json",
    )  # fmt: skip
    assert result.exit_code in (0, 1, 3), result.output
    document = json.loads(result.stdout)
    assert document["ego_b"]["params"] == {"range_scale": 1.3}
    # on the same draws the degraded sensor changes some rollouts, not all
    table = pq.read_table(tmp_path / "ab" / "samples.parquet", columns=["f_a", "f_b"])
    f_a, f_b = table["f_a"].to_numpy(), table["f_b"].to_numpy()
    assert 0 < (f_a != f_b).sum() < len(f_a)


def test_ctrl_c_says_how_to_resume_and_the_resume_gives_the_same_answer(
    short, tmp_path, monkeypatch
):
    args = ("ab", short, "--ego-b", HOLD_FAST, "--out", tmp_path / "ab", *SMALL)
    whole = invoke(*args[:4], "--out", tmp_path / "whole", *SMALL, "--json")
    with ctrl_c_at_chunk(monkeypatch, 3):
        stopped = invoke(*args)
    assert stopped.exit_code == 130
    assert "Resume with: avrisk ab" in " ".join(stopped.output.split())
    resumed = invoke(*args, "--json")
    assert resumed.exit_code == whole.exit_code == 1
    a, b = json.loads(resumed.stdout), json.loads(whole.stdout)
    assert a["paired"]["ratio"] == b["paired"]["ratio"]
    assert a["line"] == b["line"]
