"""The README's commands and code are what a user runs first: keep them true."""

import ast
import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
#: Issue 43: the README is a user's guide; figures live in BENCHMARKS.md.
README_MAX_LINES = 300


def python_blocks():
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_python_example_runs(tmp_path):
    # One fresh interpreter, the blocks in order: a block may use what an earlier
    # one defines (the Python API's example estimates with the ego class of "your
    # own AV"), and what they register stays out of this test process.
    blocks = python_blocks()
    assert blocks, "README has no python example"
    script = tmp_path / "readme_blocks.py"
    script.write_text("\n\n".join(blocks))
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-3000:]


def test_readme_is_at_most_300_lines():
    n = len(README.read_text().splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines, over {README_MAX_LINES}"


def test_an_estimation_with_a_users_ego_on_a_bundled_scenario_takes_five_lines():
    """Issue 43: what a notebook needs, in the README block that registers the ego.

    The block runs with the others in ``test_readme_python_example_runs``; here
    it is held to five statements that estimate on a bundled scenario with the
    README's own policy class, registered under the name the estimate uses.
    """
    from avrisk.scenario import bundled_scenarios

    (block,) = [b for b in python_blocks() if "register_policy(" in b]
    tree = ast.parse(block)
    assert len(tree.body) <= 5, ast.unparse(tree)
    lines = [line for line in block.splitlines() if line.strip()]
    assert len(lines) <= 5, block
    calls = {
        ast.unparse(node.func): node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
    }
    register, estimate = calls["register_policy"], calls["avrisk.estimate"]
    name, policy = (ast.literal_eval(register.args[0]), register.args[1])
    assert isinstance(policy, ast.Name) and policy.id == "HoldSpeed"
    assert any("class HoldSpeed" in b for b in python_blocks())
    assert ast.literal_eval(estimate.args[0]) in bundled_scenarios()
    options = {k.arg: ast.literal_eval(k.value) for k in estimate.keywords}
    assert options["ego"] == name


def test_readme_opens_with_the_two_fresh_machine_commands():
    head = README.read_text().split("```bash", 1)[1].split("```", 1)[0]
    assert "make demo" in head and "make test" in head
    makefile = (README.parent / "Makefile").read_text()
    assert re.search(r"^demo:", makefile, flags=re.M)
    assert re.search(r"^test:", makefile, flags=re.M)
    assert "make test" in (README.parent / ".ci" / "run").read_text()


def test_the_run_directory_table_lists_every_file_a_run_may_leave():
    """docs/report.md's table of a run directory's files, which the README links."""
    from avrisk.assembly import FAILURES_FILE
    from avrisk.pipeline.layout import (
        CHECKPOINT_FILE,
        CHUNKS_DIR,
        CONFIG_FILE,
        LOCK_FILE,
        SAMPLES_FILE,
        SUMMARY_FILE,
    )
    from avrisk.pipeline.manifest import MANIFEST_FILE
    from avrisk.pipeline.regenerate import PROPOSALS_FILE

    text = (README.parent / "docs" / "report.md").read_text()
    table = text[text.index("| file | what |") :].split("\n\n", 1)[0]
    named = set(re.findall(r"^\| ([^|]+) \|", table, flags=re.M))
    files = {f for cell in named for f in re.findall(r"`([^`]+)`", cell)}
    expected = {
        CONFIG_FILE,
        CHECKPOINT_FILE,
        PROPOSALS_FILE,
        SAMPLES_FILE,
        SUMMARY_FILE,
        MANIFEST_FILE,
        FAILURES_FILE,
        f"{CHUNKS_DIR}/",
        LOCK_FILE,
        "report.html",
        "plots/",
        "animations/",
    }
    assert expected <= files, expected - files


def test_the_readme_user_policy_is_tested_with_avrisk_run(tmp_path, monkeypatch):
    """The README's own policy, in its mypolicies.py, named as the README names it."""
    import pyarrow.parquet as pq
    import yaml
    from typer.testing import CliRunner

    from avrisk.cli.app import app
    from avrisk.pipeline.layout import CONFIG_FILE, SAMPLES_FILE
    from tests.scenario_files import shortened_scenario

    (policy,) = [b for b in python_blocks() if "class HoldSpeed" in b]
    (tmp_path / "mypolicies.py").write_text(policy)
    monkeypatch.syspath_prepend(str(tmp_path))
    line = re.search(
        r'`(ego: \{policy: "mypolicies:HoldSpeed"[^`]*)`', README.read_text()
    )
    ego = yaml.safe_load(line.group(1))["ego"]
    scenario = shortened_scenario(tmp_path, 2.0, file="my_scenario.yaml", ego=ego)
    out = tmp_path / "runs" / "mine"
    args = ["run", scenario, "--out", out, "--method", "naive", "--n-final", 64]
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    assert "mypolicies:HoldSpeed" in (out / CONFIG_FILE).read_text()
    status = pq.read_table(out / SAMPLES_FILE)["status"].to_numpy()
    assert len(status) == 64 and (status == 0).all()
