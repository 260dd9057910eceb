"""Provenance stamps: results of different probabilities are never paired."""

import pytest

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
