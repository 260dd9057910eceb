"""The scenario-level API: light to import, silent, the runs of ``avrisk run``."""

import json
import subprocess
import sys

import pytest

import avrisk
from avrisk.api import UserError, events

FAST = dict(method="naive", n_final=300, batch_size=300, failures=0)


def test_the_calls_load_neither_rich_nor_typer(tmp_path):
    code = f"""
import sys
import avrisk
assert 'torch' not in sys.modules, 'import avrisk loads the simulator'
out = {str(tmp_path / "run")!r}
avrisk.estimate('highway_idm', out=out, method='naive', n_final=200, failures=1)
avrisk.write_report(out)
avrisk.simulate('highway_idm', 50, batch_size=50)
print(sorted(m for m in ('rich', 'typer') if m in sys.modules))
"""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert done.stdout == "[]\n"
    assert done.stderr == ""  # nothing printed: progress goes to a callback


def test_estimate_writes_the_run_directory_of_avrisk_run_and_resumes(tmp_path):
    seen = []
    result = avrisk.estimate("highway_idm", out=tmp_path, progress=seen.append, **FAST)
    kinds = [type(e) for e in seen]
    assert kinds[:3] == [events.Plan, events.RunOpened, events.RunStarted]
    assert kinds[-1] is events.RunClosed and seen[-1].error is None
    assert sum(e.n for e in seen if isinstance(e, events.Advanced)) == 300
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert result.p == summary["estimate"]["p"] and result.path == tmp_path
    assert result.report == tmp_path / "report.html" and result.report.is_file()
    assert result.document()["runs"][0]["n_rollouts"] == 300
    again = []
    avrisk.estimate("highway_idm", out=tmp_path, progress=again.append, **FAST)
    assert not any(isinstance(e, events.RunStarted) for e in again)  # read back


def test_a_user_ego_by_import_path(tmp_path):
    ego = {"policy": "tests.user_components:HoldSpeedEgo", "params": {"speed": 25}}
    result = avrisk.estimate("highway_idm", out=tmp_path, ego=ego, **FAST)
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["scenario"]["ego"]["policy"] == ego["policy"]
    assert 0.0 <= result.ci[0] <= result.p <= result.ci[1]


def test_a_problem_is_one_user_error(tmp_path):
    with pytest.raises(UserError, match="never is"):
        avrisk.estimate("highway_idm", out=tmp_path, gamma=-1.0, **FAST)
    with pytest.raises(UserError, match="holds no avrisk run"):
        avrisk.write_report(tmp_path)
