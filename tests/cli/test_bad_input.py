"""Bad input and faults at the command line: one clear line, exit 2, nothing trusted.

Each class of problem is tried on every command it reaches: non-finite
thresholds, an output that cannot be written, a disk that fills up at each
phase of a run, two processes on one run directory, crafted files given to
``report`` and ``replay``, and damaged NGSIM files given to ``train-drivers``.
"""

import errno
import gzip
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

import avrisk
from avrisk.cli.app import app
from avrisk.pipeline import RunDirectoryError, RunSettings
from avrisk.pipeline.layout import LOCK_FILE
from avrisk.pipeline.lock import run_lock
from tests.scenario_files import shortened_scenario

ROOT = os.geteuid() == 0


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def one_error(result, *needles):
    """The command failed with exit code 2 and exactly one 'error:' line."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert not isinstance(result.exception, Exception) or isinstance(
        result.exception, SystemExit
    ), result.exception
    errors = [line for line in result.output.splitlines() if "error:" in line]
    assert len(errors) == 1, result.output
    message = result.output[result.output.index("error:") :]
    for needle in needles:
        assert needle in message, message
    return message


@pytest.fixture(scope="module")
def short_scenario(tmp_path_factory):
    """highway_idm with a 1.5 s horizon: runs of seconds."""
    directory = tmp_path_factory.mktemp("scenario")
    return shortened_scenario(directory, 1.5, name="highway_short")


#: A run of three chunks (two CE iterations and the final stage): seconds.
SMALL = ("--method", "ce", "--rho", 0.2, "--n-per-iter", 30, "--n-iter", 2)
SMALL += ("--n-final", 40)
SMALL += ("--batch-size", 25, "--failures", 0, "--gamma", 1.0, "--gamma-test", "0.5")


def _stray_temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".tmp-" in p.name]


# ------------------------------------------------------------- thresholds
COMMANDS = {
    "run": ("run", "highway_idm", "--method", "naive", "--n-final", 10),
    "compare": ("compare", "highway_idm", "--n-final", 10, "--reference-n", 0),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--gamma", "nan"),
        ("--gamma", "inf"),
        ("--gamma", "-inf"),
        ("--gamma-test", "0.1,nan"),
        ("--gamma-test", "inf"),
        ("--gamma-test", "0.1,-Infinity"),
        ("--gamma-test", "0.1,x"),
    ],
)
def test_a_non_finite_threshold_is_refused_before_any_work(
    tmp_path, command, flag, value
):
    out = tmp_path / "out"
    result = invoke(*COMMANDS[command], "--out", out, flag, value)
    one_error(result, flag, "finite")
    assert not out.exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize(
    ("flag", "value"), [("--gamma", "-0.1"), ("--gamma-test", "0.1,-1")]
)
def test_a_negative_threshold_on_a_time_to_collision_is_refused(
    tmp_path, command, flag, value
):
    out = tmp_path / "out"
    result = invoke(*COMMANDS[command], "--out", out, flag, value)
    one_error(result, "is negative", "min_box_ttc")
    assert not out.exists()


@pytest.mark.parametrize(
    "kwargs",
    [{"gamma": float("nan")}, {"gamma": np.inf}, {"gamma_test": [0.1, np.nan]}],
)
def test_run_settings_refuse_non_finite_thresholds(kwargs):
    with pytest.raises(ValueError, match="must be finite"):
        RunSettings("naive", n_final=10, **kwargs)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("--n-final", 0), "n_final"),
        (("--method", "ce", "--n-per-iter", 0), "n_per_iter"),
        (("--batch-size", 0), "--batch-size"),
        (("--max-rollouts", 0), "--max-rollouts"),
        (("--max-time", -1), "max_seconds"),
        (("--max-time", "nan"), "max_seconds"),
        (("--target-rel-half-width", 0), "rel_half_width"),
        (("--target-rel-half-width", "nan"), "rel_half_width"),
        (("--method", "ce", "--rho", "nan"), "rho"),
        (("--method", "ce", "--alpha", "inf"), "alpha"),
        (("--set", "n_final=-5"), "n_final"),
        (("--seed", -1), "--seed"),
    ],
)
def test_a_meaningless_count_or_limit_is_refused_before_any_work(
    tmp_path, args, needle
):
    out = tmp_path / "out"
    result = invoke("run", "highway_idm", "--out", out, *args)
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert needle in result.output
    assert not out.exists()


def test_splitting_whose_levels_cannot_reach_gamma_says_caution_not_an_error(
    short_scenario, tmp_path
):
    """Levels that stall above gamma give naive sampling's bound, with caution."""
    out = tmp_path / "out"
    result = invoke(
        "run", short_scenario, "--out", out, "--method", "splitting",
        "--set", "n_particles=40", "--set", "max_levels=1", "--gamma", 0.01,
        "--failures", 0,
    )  # fmt: skip
    assert result.exit_code == 0 and "Traceback" not in result.output
    assert "trust: caution" in result.output
    assert "did not reach gamma within max_levels levels" in result.output


# ---------------------------------------------------------------- outputs
FOLDER_COMMANDS = {
    "run": lambda out: ("run", "highway_idm", "--out", out, "--n-final", 10),
    "compare": lambda out: ("compare", "highway_idm", "--out", out),
    "demo": lambda out: ("demo", "--scenario-out", out),
}
FILE_COMMANDS = {
    "simulate": lambda out: ("simulate", "highway_idm", "--out", out, "--n", 2),
    "demo": lambda out: ("demo", "--out", out, "--rollouts", 0),
}


def _unwritable(tmp_path: Path) -> Path:
    """A folder this process cannot write in, even as root."""
    if ROOT:
        return Path("/proc/avrisk-test")  # the kernel refuses root too
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    return folder


@pytest.mark.parametrize("command", sorted(FOLDER_COMMANDS))
@pytest.mark.parametrize("case", ["a-file", "under-a-file", "unwritable"])
def test_an_output_folder_that_cannot_be_written_is_refused_first(
    tmp_path, command, case
):
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    out, needle = {
        "a-file": (a_file, "is a file"),
        "under-a-file": (a_file / "run", "is a file, so no folder can be made"),
        "unwritable": (_unwritable(tmp_path) / "run", "cannot create that folder in"),
    }[case]
    message = one_error(invoke(*FOLDER_COMMANDS[command](out)), str(out), needle)
    assert "No such file" not in message  # /proc takes no new files: said so
    assert a_file.read_text() == "not a folder"
    assert out == a_file or not out.exists()


@pytest.mark.parametrize("command", sorted(FILE_COMMANDS))
@pytest.mark.parametrize(
    "case", ["a-folder", "under-a-file", "no-folder", "unwritable"]
)
def test_an_output_file_that_cannot_be_written_is_refused_first(
    tmp_path, command, case
):
    suffix = ".parquet" if command == "simulate" else ".json"
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    (tmp_path / f"folder{suffix}").mkdir()
    out, needle = {
        "a-folder": (tmp_path / f"folder{suffix}", "is a folder"),
        "under-a-file": (a_file / f"out{suffix}", "does not exist"),
        "no-folder": (tmp_path / "missing" / f"out{suffix}", "does not exist"),
        "unwritable": (_unwritable(tmp_path) / f"out{suffix}", "cannot write in"),
    }[case]
    if case == "unwritable" and ROOT:
        needle = "does not exist"  # /proc/avrisk-test: no such folder
    one_error(invoke(*FILE_COMMANDS[command](out)), needle)


def test_a_read_only_file_system_is_refused_first(tmp_path, monkeypatch):
    """A read-only mount, emulated: creating any file fails with EROFS."""
    import avrisk.cli.common as common

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(common.tempfile, "TemporaryFile", read_only)
    out = tmp_path / "run"
    one_error(
        invoke("run", "highway_idm", "--out", out),
        "cannot create that folder in",
        "Read-only file system",
    )
    one_error(
        invoke("simulate", "highway_idm", "--out", tmp_path / "x.parquet"),
        "Read-only file system",
    )
    assert not out.exists()


# ---------------------------------------------------------- a full disk
def _full_disk(exc_path: Path) -> OSError:
    return OSError(errno.ENOSPC, "No space left on device", str(exc_path))


@pytest.fixture(scope="module")
def clean_estimate(short_scenario, tmp_path_factory):
    """The estimate of the naive run below, uninterrupted."""
    out = tmp_path_factory.mktemp("clean") / "run"
    result = invoke("run", short_scenario, "--out", out, *SMALL)
    assert result.exit_code == 0, result.output
    return json.loads((out / "summary.json").read_text())["estimate"]


def _same_estimate(out: Path, clean: dict) -> None:
    estimate = json.loads((out / "summary.json").read_text())["estimate"]
    timeless = {k: v for k, v in estimate.items() if "time" not in k}
    assert timeless == {k: v for k, v in clean.items() if "time" not in k}


def test_a_disk_full_while_recording_a_chunk_leaves_a_resumable_run(
    short_scenario, tmp_path, monkeypatch, clean_estimate
):
    out = tmp_path / "run"
    real = Path.write_bytes
    chunks_written = []

    def fills_up(self, data):
        if self.name.startswith(".stage") and ".tmp-" in self.name:
            chunks_written.append(self.name)
            if len(chunks_written) == 3:  # half the final chunk, then no room
                real(self, data[: len(data) // 2])
                raise _full_disk(self)
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", fills_up)
    one_error(
        invoke("run", short_scenario, "--out", out, *SMALL),
        "No space left on device",
        "rerun the same command to resume",
    )
    monkeypatch.undo()
    assert _stray_temporaries(out) == []
    assert len(list((out / "chunks").glob("*.parquet"))) == 2
    assert not (out / "summary.json").exists()
    resumed = invoke("run", short_scenario, "--out", out, *SMALL)
    assert resumed.exit_code == 0, resumed.output
    _same_estimate(out, clean_estimate)


@pytest.mark.parametrize("name", ["config.json", "checkpoint.json"])
def test_a_disk_full_before_any_chunk_leaves_no_directory(
    short_scenario, tmp_path, monkeypatch, name
):
    out = tmp_path / "run"
    real = Path.write_bytes

    def fills_up(self, data):
        if self.name.startswith(f".{name}.tmp-"):
            raise _full_disk(self)
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", fills_up)
    one_error(
        invoke("run", short_scenario, "--out", out, *SMALL), "No space left on device"
    )
    # The first chunk is recorded before the first checkpoint: that run resumes.
    assert not out.exists() if name == "config.json" else _stray_temporaries(out) == []


def test_a_disk_full_while_gathering_the_samples_leaves_a_resumable_run(
    short_scenario, tmp_path, monkeypatch, clean_estimate
):
    out = tmp_path / "run"

    import avrisk.pipeline.samples as samples

    def fills_up(table, schema):  # the temporary samples file is open by then
        raise _full_disk(out / "samples.parquet")

    monkeypatch.setattr(samples, "conformed", fills_up)
    one_error(
        invoke("run", short_scenario, "--out", out, *SMALL),
        "No space left on device",
        "resume",
    )
    monkeypatch.undo()
    assert _stray_temporaries(out) == []
    assert not (out / "summary.json").exists()
    assert not (out / "samples.parquet").exists()
    # every chunk evaluated is kept: the search's, the final stage's, the audit's
    stages = {c.name[:9] for c in (out / "chunks").glob("*.parquet")}
    assert {"stage0000", "stage0001", "stage0002", "stage0003"} <= stages
    resumed = invoke("run", short_scenario, "--out", out, *SMALL)
    assert resumed.exit_code == 0, resumed.output
    _same_estimate(out, clean_estimate)


def test_a_disk_full_while_writing_the_report_says_the_run_is_complete(
    short_scenario, tmp_path, monkeypatch, clean_estimate
):
    import avrisk.report.html as html

    out = tmp_path / "run"
    assert invoke("run", short_scenario, "--out", out, *SMALL).exit_code == 0
    (out / "report.html").unlink()

    def fills_up(path, data):
        raise _full_disk(path)

    monkeypatch.setattr(html, "write_atomic", fills_up)
    one_error(
        invoke("report", out),
        "No space left on device",
        "the run itself is complete",
        f"avrisk report {out}",
    )
    assert not (out / "report.html").exists()
    _same_estimate(out, clean_estimate)


def test_write_atomic_leaves_no_temporary_when_the_disk_fills(tmp_path, monkeypatch):
    from avrisk.pipeline.files import write_atomic

    real = Path.write_bytes

    def fills_up(self, data):
        real(self, data[:3])
        raise _full_disk(self)

    monkeypatch.setattr(Path, "write_bytes", fills_up)
    with pytest.raises(OSError, match="No space"):
        write_atomic(tmp_path / "x.json", "{}" * 100)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------- two processes, one dir
_HOLDER = (
    "import sys, time\n"
    "from pathlib import Path\n"
    "from avrisk.pipeline.lock import run_lock\n"
    "with run_lock(Path(sys.argv[1])):\n"
    "    print('locked', flush=True)\n"
    "    time.sleep(600)\n"
)


@pytest.fixture
def lock_holder(tmp_path):
    """A separate process holding the lock of ``tmp_path / 'run'``."""
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(Path(avrisk.__file__).parents[1])}
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(out)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
    yield out, proc
    proc.kill()
    proc.wait()


def test_a_second_process_on_a_run_directory_is_refused_naming_the_first(
    lock_holder, short_scenario
):
    out, proc = lock_holder
    with pytest.raises(RunDirectoryError, match=f"pid {proc.pid}"):
        with run_lock(out):
            pass
    one_error(
        invoke("run", short_scenario, "--out", out, *SMALL),
        "in use by another avrisk process",
        f"pid {proc.pid}",
    )
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]


def test_the_lock_of_a_killed_process_does_not_block(lock_holder, short_scenario):
    out, proc = lock_holder
    proc.kill()  # SIGKILL: no clean-up runs, the lock file stays
    proc.wait()
    assert (out / LOCK_FILE).read_text().strip() == str(proc.pid)
    with run_lock(out):
        assert (out / LOCK_FILE).read_text().strip() == str(os.getpid())
    result = invoke("run", short_scenario, "--out", out, *SMALL)
    assert result.exit_code == 0, result.output


def test_the_lock_is_released_and_reacquired_in_one_process(tmp_path):
    with run_lock(tmp_path / "run"):
        pass
    with run_lock(tmp_path / "run"):
        pass
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunDirectoryError, match="is a file"):
        with run_lock(tmp_path / "file"):
            pass


# ------------------------------------------- report and replay, crafted files
@pytest.fixture(scope="module")
def finished_run(short_scenario, tmp_path_factory):
    out = tmp_path_factory.mktemp("finished") / "run"
    result = invoke("run", short_scenario, "--out", out, *SMALL)
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def simulated(short_scenario, tmp_path_factory):
    out = tmp_path_factory.mktemp("simulated") / "rollouts.parquet"
    result = invoke("simulate", short_scenario, "--out", out, "--n", 6)
    assert result.exit_code == 0, result.output
    return out


def _edit_json(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def _set_column(path: Path, name: str, values, out: Path | None = None) -> None:
    """Replace column ``name``: ``values`` a list, or one value for every row."""
    table = pq.read_table(path)
    i = table.column_names.index(name)
    column = pa.array(values if isinstance(values, list) else [values] * len(table))
    table = table.set_column(i, pa.field(name, column.type), column)
    pq.write_table(table, out or path)


def _set_row(path: Path, name: str, row: int, value: float) -> None:
    table = pq.read_table(path)
    values = table.column(name).to_pylist()
    values[row] = value
    _set_column(path, name, values)


def _drop_column(path: Path, name: str) -> None:
    pq.write_table(pq.read_table(path).drop([name]), path)


def _huge_horizon(scenario: dict) -> None:
    scenario["simulation"].update(dt=1e-9, horizon=600.0)


RUN_DAMAGE = {
    "config-not-json": (
        lambda d: (d / "config.json").write_text("{not json"),
        "not valid JSON",
    ),
    "config-empty": (lambda d: (d / "config.json").write_text(""), "not valid JSON"),
    "config-a-list": (
        lambda d: (d / "config.json").write_text("[1, 2]"),
        "not an object",
    ),
    "config-no-scenario": (
        lambda d: _edit_json(d / "config.json", lambda c: c.pop("scenario")),
        "holds no 'scenario' section",
    ),
    "config-endless-horizon": (
        lambda d: _edit_json(d / "config.json", lambda c: _huge_horizon(c["scenario"])),
        "config.json: invalid scenario:",
    ),
    "summary-not-json": (
        lambda d: (d / "summary.json").write_text("garbage"),
        "not valid JSON",
    ),
    "summary-nan": (
        lambda d: (d / "summary.json").write_text(
            (d / "summary.json").read_text().replace('"p": ', '"p": NaN, "was": ', 1)
        ),
        "NaN is not a number JSON allows",
    ),
    "summary-wrong-shape": (
        lambda d: (d / "summary.json").write_text('{"estimate": {"by_gamma": "x"}}'),
        "not an avrisk summary",
    ),
    "summary-p-text": (
        lambda d: _edit_json(
            d / "summary.json", lambda s: s["estimate"]["by_gamma"][0].update(p="abc")
        ),
        "by_gamma.0.p",
    ),
    "summary-negative-p": (
        lambda d: _edit_json(
            d / "summary.json", lambda s: s["estimate"].update(p=-1.0)
        ),
        "estimate.p",
    ),
    "summary-no-main-threshold": (
        lambda d: _edit_json(
            d / "summary.json", lambda s: s["estimate"].update(gamma=9.0)
        ),
        "no estimate at its own threshold",
    ),
    "summary-tampered-p": (  # well-formed, but not what the run wrote
        lambda d: _edit_json(
            d / "summary.json", lambda s: s["estimate"].update(p=s["estimate"]["p"] * 2)
        ),
        "summary.json: SHA-256",
    ),
    "samples-tampered-f": (
        lambda d: _set_row(d / "samples.parquet", "f", 0, 0.123),
        "samples.parquet: SHA-256",
    ),
    "samples-garbage": (
        lambda d: (d / "samples.parquet").write_bytes(b"garbage" * 100),
        "not a readable Parquet file",
    ),
    "samples-truncated": (
        lambda d: (d / "samples.parquet").write_bytes(
            (d / "samples.parquet").read_bytes()[:500]
        ),
        "not a readable Parquet file",
    ),
    "samples-missing": (lambda d: (d / "samples.parquet").unlink(), "missing"),
    "samples-no-f": (
        lambda d: _drop_column(d / "samples.parquet", "f"),
        "lacks column(s) ['f']",
    ),
    "samples-f-text": (
        lambda d: _set_column(d / "samples.parquet", "f", "x"),
        "column 'f' holds string",
    ),
    "samples-seed-float": (
        lambda d: _set_column(d / "samples.parquet", "seed", 0.5),
        "column 'seed' holds double, not integers",
    ),
}


@pytest.mark.parametrize("damage", sorted(RUN_DAMAGE))
def test_report_refuses_a_damaged_run_in_one_line(finished_run, tmp_path, damage):
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    (run / "report.html").unlink()
    edit, needle = RUN_DAMAGE[damage]
    edit(run)
    result = invoke("report", run)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and needle in result.output
    assert not (run / "report.html").exists()


@pytest.mark.parametrize(
    "damage", ["config-not-json", "config-no-scenario", "summary-wrong-shape"]
)
def test_rerunning_run_on_a_damaged_run_is_one_line(
    finished_run, short_scenario, tmp_path, damage
):
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    edit, needle = RUN_DAMAGE[damage]
    edit(run)
    one_error(invoke("run", short_scenario, "--out", run, *SMALL), needle)


def test_rerunning_run_on_a_tampered_summary_recomputes_it(
    finished_run, short_scenario, tmp_path
):
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    before = json.loads((run / "summary.json").read_text())["estimate"]
    RUN_DAMAGE["summary-tampered-p"][0](run)
    result = invoke("run", short_scenario, "--out", run, *SMALL)
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())  # warnings wrap at the terminal's width
    assert "summary.json: SHA-256" in said and "recomputing" in said
    after = json.loads((run / "summary.json").read_text())["estimate"]
    assert after["p"] == before["p"] and after["n_evals"] == before["n_evals"]


def _meta(path: Path, key: bytes, value: bytes) -> None:
    table = pq.read_table(path)
    meta = dict(table.schema.metadata)
    meta[key] = value
    pq.write_table(table.replace_schema_metadata(meta), path)


def _meta_scenario(path: Path, edit) -> None:
    meta = pq.read_schema(path).metadata
    scenario = json.loads(meta[b"avrisk.scenario"])
    edit(scenario)
    _meta(path, b"avrisk.scenario", json.dumps(scenario).encode())


REPLAY_DAMAGE = {
    "garbage": (lambda p: p.write_bytes(b"junk" * 50), "not a readable Parquet file"),
    "empty": (lambda p: p.write_bytes(b""), "not a readable Parquet file"),
    "meta-not-json": (
        lambda p: _meta(p, b"avrisk.scenario", b"{nope"),
        "not valid JSON",
    ),
    "meta-a-list": (
        lambda p: _meta(p, b"avrisk.scenario", b"[1]"),
        "must be a mapping",
    ),
    "meta-endless-horizon": (
        lambda p: _meta_scenario(p, _huge_horizon),
        "time steps per rollout",
    ),
    "nan-in-row": (
        lambda p: _set_row(p, "veh0.speed", 0, float("nan")),
        "veh0.speed is nan",
    ),
    "inf-in-row": (lambda p: _set_row(p, "veh1.s", 0, float("inf")), "veh1.s is inf"),
    "absurd-in-row": (
        lambda p: _set_row(p, "veh0.speed", 0, 1e30),
        "veh0.speed = 1e+30 lies outside its range",
    ),
    "f-text": (lambda p: _set_column(p, "f", ["x"] * 6), "column 'f' holds string"),
    "seed-text": (
        lambda p: _set_column(p, "seed", ["x"] * 6),
        "column 'seed' holds string",
    ),
    "no-seed": (lambda p: _drop_column(p, "seed"), "lacks column(s) ['seed']"),
    "x-text": (
        lambda p: _set_column(p, "veh2.t", ["a"] * 6),
        "column 'veh2.t' holds string",
    ),
}


@pytest.mark.parametrize("worst", [False, True])
@pytest.mark.parametrize("damage", sorted(REPLAY_DAMAGE))
def test_replay_refuses_a_crafted_samples_file_in_one_line(
    simulated, tmp_path, damage, worst
):
    path = tmp_path / "rollouts.parquet"
    shutil.copyfile(simulated, path)
    edit, needle = REPLAY_DAMAGE[damage]
    edit(path)
    pick = ("--worst", 6) if worst else ("--rows", "0,1")
    out = tmp_path / "replay.gif"
    one_error(invoke("replay", path, *pick, "--out", out), needle)
    assert not out.exists()


@pytest.mark.parametrize(
    "damage", ["config-not-json", "config-a-list", "config-no-scenario"]
)
def test_replay_of_a_run_with_a_damaged_config_is_one_line(
    finished_run, tmp_path, damage
):
    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    edit, needle = RUN_DAMAGE[damage]
    edit(run)
    one_error(invoke("replay", run, "--rows", 0, "--out", tmp_path / "r.gif"), needle)


# --------------------------------------------- train-drivers --data-dir
def _garbage(path: Path) -> None:
    path.write_bytes(os.urandom(3000))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _csv_wrong_columns(path: Path) -> None:
    with gzip.open(path, "wt") as f:
        f.write("a,b\n1,2\n")


def _parquet_wrong_columns(path: Path) -> None:
    pq.write_table(pa.table({"a": [1, 2]}), path)


def _parquet_text_column(path: Path) -> None:
    table = pq.read_table(path)
    _set_column(path, "local_y", ["x"] * table.num_rows)


PAIRS, LATERAL = "i80_cf_pairs.csv.gz", "i80_0400_0415_emd_cf_pairs.parquet"


@pytest.mark.parametrize(
    ("name", "damage", "needle"),
    [
        (PAIRS, _garbage, "not readable"),
        (PAIRS, _truncate, "not readable"),
        (PAIRS, _csv_wrong_columns, "lacks the columns"),
        (LATERAL, _garbage, "not readable"),
        (LATERAL, _truncate, "not readable"),
        (LATERAL, _parquet_wrong_columns, "lacks the columns"),
        (LATERAL, _parquet_text_column, "not NGSIM data"),
    ],
    ids=[
        "gzip-garbage",
        "gzip-truncated",
        "csv-wrong-columns",
        "parquet-garbage",
        "parquet-truncated",
        "parquet-wrong-columns",
        "parquet-text-column",
    ],
)
def test_train_drivers_refuses_damaged_data_before_training(
    fake_ngsim, tmp_path, name, damage, needle
):
    damage(fake_ngsim / name)
    out = tmp_path / "drivers"
    one_error(
        invoke("train-drivers", "--data-dir", fake_ngsim, "--out", out),
        "--data-dir",
        str(fake_ngsim / name),
        needle,
    )
    assert not out.exists()
