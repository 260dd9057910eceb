"""What a new user gets wrong first, each answered in one line (no traceback).

A misspelt ego, an unknown or unsafe parameter of the external ego, an
install without an optional extra, a folder of the user's given as ``--out``
and a run whose recorded chunks were deleted: the command ends with one red
line and exit status 2, naming the problem and what to do.
"""

import shutil
import sys

import pytest

from tests.cli.test_bad_input import SMALL, invoke, one_error
from tests.interrupts import ctrl_c_at_chunk
from tests.scenario_files import shortened_scenario

ARGS = ("--method", "naive", "--n-final", 10, "--failures", 0)


def _with_ego(tmp_path, ego):
    return shortened_scenario(tmp_path, 1.0, ego=ego)


@pytest.mark.parametrize("command", ["run", "simulate"])
def test_a_misspelt_ego_is_one_line_with_the_name_meant(tmp_path, command):
    path = _with_ego(tmp_path, {"policy": "idm_mobill"})
    out, extra = (
        (tmp_path / "out", ARGS)
        if command == "run"
        else (tmp_path / "out.parquet", ("--n", 4))
    )
    result = invoke(command, path, "--out", out, *extra)
    one_error(result, "unknown ego policy 'idm_mobill'", "did you mean 'idm_mobil'?")
    assert not out.exists()


@pytest.mark.parametrize(
    ("params", "needles"),
    [
        ({"bogus": 1}, ["params.bogus: unknown", "allowed: address, timeout_s"]),
        ({"timeout": 1}, ["params.timeout: unknown", "did you mean 'timeout_s'?"]),
        (
            {"address": "tcp://192.0.2.1:5556"},
            ["leaves this machine", "set allow_remote: true"],
        ),
    ],
)
def test_a_bad_param_of_the_external_ego_is_one_line(tmp_path, params, needles):
    path = _with_ego(tmp_path, {"policy": "external", "params": params})
    result = invoke("run", path, "--out", tmp_path / "out", *ARGS)
    one_error(result, "ego policy 'external'", *needles)


def _uninstalled(monkeypatch, *modules):
    """Make ``modules`` unimportable and forget avrisk's modules that import them."""
    for name in list(sys.modules):
        if name.startswith(("avrisk.agents.external.", "avrisk.gym")) and not (
            name.endswith((".params", ".spaces"))
        ):
            monkeypatch.delitem(sys.modules, name)
    for name in modules:
        monkeypatch.setitem(sys.modules, name, None)


@pytest.mark.parametrize("missing", ["zmq", "msgpack"])
def test_the_external_ego_without_its_extra_says_what_to_install(
    tmp_path, monkeypatch, missing
):
    _uninstalled(monkeypatch, missing)
    install = "pip install 'avrisk[external]'"
    path = _with_ego(tmp_path, {"policy": "external"})
    result = invoke("run", path, "--out", tmp_path / "out", *ARGS)
    one_error(result, "the external ego needs pyzmq and msgpack", install)
    result = invoke("serve-ego", "--address", f"ipc://{tmp_path}/no/such/dir")
    one_error(result, "the external ego needs pyzmq and msgpack", install)


def test_avrisk_gym_without_gymnasium_is_an_import_error_naming_the_extra(
    monkeypatch,
):
    _uninstalled(monkeypatch, "gymnasium")
    with pytest.raises(ImportError, match=r"pip install 'avrisk\[gymnasium\]'"):
        import avrisk.gym  # noqa: F401


def _tree(folder):
    return sorted(
        (str(p.relative_to(folder)), p.stat().st_mtime_ns) for p in folder.rglob("*")
    )


def test_a_folder_of_the_users_given_as_out_is_refused_and_left_as_found(tmp_path):
    out = tmp_path / "mine"
    (out / "data").mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    before = _tree(out)
    result = invoke("run", "highway_idm", "--out", out, *ARGS)
    one_error(result, "is not an avrisk run directory", "choose an empty or new")
    assert _tree(out) == before  # no .lock, nothing touched


def test_an_unfinished_run_whose_chunks_were_deleted_is_one_line(tmp_path, monkeypatch):
    scenario, out = _with_ego(tmp_path, {"policy": "idm_mobil"}), tmp_path / "run"
    args = ("run", scenario, "--out", out, *SMALL)  # three chunks
    with ctrl_c_at_chunk(monkeypatch, 2):
        assert invoke(*args).exit_code == 130
    shutil.rmtree(out / "chunks")
    one_error(invoke(*args), "unfinished run whose chunks/ folder", f"delete {out}")
