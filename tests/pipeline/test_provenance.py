"""Provenance stamps: results of different probabilities are never paired."""

import shutil
import subprocess

import pytest

import avrisk
import avrisk.version
from avrisk.fingerprint import sha256_json
from avrisk.pipeline.provenance import (
    ProvenanceMismatchError,
    check_same_definition,
    code_version,
    stamp,
)

DEFINES = {"scenario_sha256": sha256_json({"name": "a"}), "weights_sha256": {}}


def test_a_stamp_says_what_defines_p_and_how_it_was_computed():
    s = stamp(DEFINES, {"device": "cpu", "precision": "float32"})
    assert s["defines_p"] == DEFINES
    assert s["computed_with"]["device"] == "cpu"
    assert s["computed_with"]["avrisk"] == code_version()["avrisk"]


def test_a_reference_of_another_scenario_or_weights_is_refused_by_name():
    mine = stamp(DEFINES, {"device": "cpu"})
    other = stamp({**DEFINES, "weights_sha256": {"driver_net.npz": "0" * 64}}, {})
    with pytest.raises(ProvenanceMismatchError, match="differs in: weights_sha256"):
        check_same_definition(mine, other, "the reference run")


def test_other_computations_of_the_same_p_are_shown_not_refused():
    mine = stamp(DEFINES, {"device": "cpu", "precision": "float32"})
    gpu = stamp(DEFINES, {"device": "cuda:0", "precision": "float32"})
    notes = check_same_definition(mine, gpu, "the reference run")
    assert notes == [
        "the reference run was computed with device = 'cuda:0' (this run: 'cpu')"
    ]
    assert "no provenance stamp" in check_same_definition(mine, None, "it")[0]


def _repository(folder, pyproject):
    """A git repository at ``folder`` with one commit; its HEAD."""
    folder.mkdir(parents=True, exist_ok=True)
    if pyproject is not None:
        (folder / "pyproject.toml").write_text(pyproject)
    git = ["git", "-C", str(folder), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "commit", "-q", "--allow-empty", "-m", "x"], check=True)
    done = subprocess.run([*git, "rev-parse", "HEAD"], check=True, capture_output=True)
    return done.stdout.decode().strip()


def _installed_at(monkeypatch, package):
    package.mkdir(parents=True, exist_ok=True)
    (package / "__init__.py").write_text("")
    monkeypatch.setattr(avrisk.version, "__file__", str(package / "version.py"))


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_only_an_avrisk_checkout_stamps_its_git_commit(tmp_path, monkeypatch):
    ours = _repository(tmp_path / "checkout", '[project]\nname = "avrisk"\n')
    _installed_at(monkeypatch, tmp_path / "checkout" / "avrisk")
    assert code_version()["git_commit"] == ours
    # installed in a virtual environment inside the user's repository
    _repository(tmp_path / "user", '[project]\nname = "mine"\n')
    site = tmp_path / "user" / ".venv" / "lib" / "site-packages"
    _installed_at(monkeypatch, site / "avrisk")
    assert code_version() == {
        "avrisk": avrisk.__version__,
        "git_commit": None,
        "git_dirty": None,
    }
    # a package at the top of a repository that is not avrisk's
    _installed_at(monkeypatch, tmp_path / "user" / "avrisk")
    assert code_version()["git_commit"] is None
    (tmp_path / "user" / "pyproject.toml").write_text("[project\nname = ")
    assert code_version()["git_commit"] is None  # unreadable: not avrisk's
