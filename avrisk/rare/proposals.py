"""A stage's sampling distribution as a JSON record, to draw its samples again.

Chunk ``j`` of stage ``s`` of a run with seed ``seed`` is
``proposal.sample(size, chunk_rng(seed, s, j))``
(:func:`avrisk.rare.stages.chunk_task`), so whoever records the proposal can
draw the chunk again, bit for bit, instead of storing it. Every sampler the
estimators use is the base distribution's structure at other parameters, or a
mixture of such members with the base:

================  ============================================================
``family``        one member: its :meth:`~ExponentialFamily.exact_params`
``defensive``     :class:`DefensiveMixture`: the member and the base's weight
``mixture``       :class:`MixtureProposal`: members, their weights, the
                  defensive share
================  ============================================================

A record with ``"space": "standard"`` holds members that shift the base's
standard normals (:class:`~avrisk.rare.families.StandardSpaceShift`) by
their shift ``mu``; one with ``"space": "standard-scaled"`` members that also
scale them
(:class:`~avrisk.rare.families.standard_space_normal.StandardSpaceNormal`),
by ``mu`` followed by the variances ``v``.

The record holds numbers only (floats written by ``json`` round-trip
exactly); the structure (covariances, supports, search boxes) comes from the
base the reader passes in. A record read from disk is untrusted: a malformed
one is a ValueError, never an exception from deep inside a family.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from avrisk.rare.defensive import DefensiveMixture
from avrisk.rare.families.base import ExponentialFamily, FloatArray
from avrisk.rare.families.standard_space import StandardSpaceShift
from avrisk.rare.families.standard_space_normal import StandardSpaceNormal
from avrisk.rare.mixture_em import MixtureProposal

__all__ = [
    "Sampler",
    "mixture_from_estimate",
    "proposal_from_record",
    "proposal_record",
]

#: The spaces a record's members may live in.
SPACES = ("natural", "standard", "standard-scaled")

#: What a stage samples from.
Sampler = ExponentialFamily | DefensiveMixture | MixtureProposal


def proposal_record(
    proposal: Sampler, base: ExponentialFamily
) -> dict[str, Any] | None:
    """JSON-ready record of ``proposal`` relative to ``base``, or None.

    None for a sampler of another kind (its samples cannot be drawn again from
    a record and must be stored). Members that shift the base's standard
    normals (:class:`StandardSpaceShift`) are recorded by their shift, with
    ``"space": "standard"``.

    The sampler's base need not be ``base`` itself, only of its kind (a run
    directory builds its own ``P0`` from the scenario): numbers recorded on
    another structure draw other samples, which is why a run directory draws
    a chunk again from its record and compares the bits before leaving
    anything out (:mod:`avrisk.pipeline.regenerate`).
    """
    if isinstance(proposal, DefensiveMixture | MixtureProposal):
        if not _same_kind(proposal.base, base):
            return None
        members = (
            [proposal.proposal]
            if isinstance(proposal, DefensiveMixture)
            else list(proposal.components)
        )
        records = [_member_record(m, base) for m in members]
        spaces = {r[0] for r in records if r is not None}
        if any(r is None for r in records) or len(spaces) != 1:
            return None
        params = [r[1] for r in records if r is not None]
        space = _space_field(spaces.pop())
        if isinstance(proposal, DefensiveMixture):
            return {
                "kind": "defensive",
                "weight": proposal.weight,
                "params": params[0],
                **space,
            }
        return {
            "kind": "mixture",
            "defensive": proposal.defensive,
            "weights": _floats(proposal.weights),
            "components": params,
            **space,
        }
    record = _member_record(proposal, base)
    if record is None:
        return None
    return {"kind": "family", "params": record[1], **_space_field(record[0])}


def _space_field(space: str) -> dict[str, str]:
    """The record's ``"space"`` entry (none for the natural space)."""
    return {} if space == "natural" else {"space": space}


def _member_record(
    member: Any, base: ExponentialFamily
) -> tuple[str, list[float]] | None:
    """``(space, params)`` of one member of ``base``'s families, or None."""
    if isinstance(member, StandardSpaceShift) and _same_kind(member.base, base):
        return "standard", _floats(member.mean)
    if isinstance(member, StandardSpaceNormal) and _same_kind(member.base, base):
        return "standard-scaled", _floats(
            np.concatenate([member.mean, member.variance])
        )
    if isinstance(member, ExponentialFamily) and type(member) is type(base):
        return "natural", _floats(member.exact_params())
    return None


def _same_kind(one: ExponentialFamily, other: ExponentialFamily) -> bool:
    """Whether two bases are of one type and dimension (the same, or rebuilt)."""
    return one is other or (type(one) is type(other) and one.dim == other.dim)


def proposal_from_record(record: Any, base: ExponentialFamily) -> Sampler:
    """The sampler of :func:`proposal_record`, on ``base``'s structure.

    Raises
    ------
    ValueError
        If ``record`` is not such a record for ``base`` (says what is wrong).
    """
    if not isinstance(record, dict) or "kind" not in record:
        raise ValueError(
            f"a proposal record is an object with a 'kind'; got {record!r:.80}"
        )
    kind = record["kind"]
    space = record.get("space", "natural")
    if space not in SPACES:
        raise ValueError(f"proposal record: unknown space {space!r:.40}")
    if kind == "family":
        return _member(record.get("params"), base, space)
    if kind == "defensive":
        return DefensiveMixture(
            _member(record.get("params"), base, space),
            base,
            _number(record, "weight"),
        )
    if kind == "mixture":
        components = record.get("components")
        if not isinstance(components, list) or not components:
            raise ValueError("a mixture record needs a non-empty list of components")
        weights = _vector(record.get("weights"), len(components), "weights")
        mixture = MixtureProposal(
            [_member(c, base, space) for c in components],
            weights,
            base,
            _number(record, "defensive"),
        )
        mixture.weights = weights  # as recorded: normalising again may move a bit
        return mixture
    raise ValueError(f"unknown proposal kind {kind!r} (family, defensive, mixture)")


#: The standard-space members an estimate's ``to_dict`` names, and their space.
_ESTIMATE_MEMBERS = {
    "StandardSpaceShift": "standard",
    "StandardSpaceNormal": "standard-scaled",
}


def mixture_from_estimate(description: Any, base: ExponentialFamily) -> MixtureProposal:
    """The standard-space mixture an estimate describes, read back on ``base``.

    The description is ``Estimate.to_dict()["proposal"]``: ``splitting_is``
    fits a :class:`MixtureProposal` of standard-space shifts (or shifts with
    fitted variances), and its ``to_dict`` names each member's mean (and
    variance) as a run summary keeps them. This reads
    that description back on ``base``'s structure, through
    :func:`proposal_from_record`. Whether it is the distribution the samples
    came from is for the caller to check (their recorded densities).

    Raises
    ------
    ValueError
        If ``description`` is not such a mixture (says what is wrong).
    """
    if not isinstance(description, dict) or description.get("family") != "Mixture":
        raise ValueError("not the description of a mixture proposal")
    members = description.get("components")
    if not isinstance(members, list) or not members:
        raise ValueError("a mixture description needs a list of components")
    spaces = {
        _ESTIMATE_MEMBERS.get(m.get("family")) if isinstance(m, dict) else None
        for m in members
    }
    if len(spaces) != 1 or None in spaces:
        raise ValueError("the mixture's members are not all of one standard-space kind")
    space = spaces.pop()

    def params(member: dict[str, Any]) -> list[Any]:
        mean = list(member.get("mean") or [])
        return (
            mean + list(member.get("variance") or []) if space != "standard" else mean
        )

    mixture = proposal_from_record(
        {
            "kind": "mixture",
            "defensive": description.get("defensive"),
            "weights": description.get("weights"),
            "components": [params(m) for m in members],
            "space": space,
        },
        base,
    )
    assert isinstance(mixture, MixtureProposal)
    return mixture


def _member(params: Any, base: ExponentialFamily, space: str) -> ExponentialFamily:
    if space == "standard":
        return StandardSpaceShift(base, _vector(params, base.dim, "params"))
    if space == "standard-scaled":
        values = _vector(params, 2 * base.dim, "params")
        if not (values[base.dim :] > 0).all():
            raise ValueError("proposal record: variances must be positive")
        return StandardSpaceNormal(base, values[: base.dim], values[base.dim :])
    return base.with_exact_params(_vector(params, base.n_stats, "params"))


def _vector(values: Any, n: int, name: str) -> FloatArray:
    if not isinstance(values, list) or len(values) != n:
        raise ValueError(f"proposal record: {name} must be a list of {n} numbers")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise ValueError(f"proposal record: {name} must hold numbers only")
    out = np.array(values, dtype=np.float64)
    if not np.isfinite(out).all():
        raise ValueError(f"proposal record: {name} must be finite")
    return out


def _number(record: dict[str, Any], name: str) -> float:
    return float(_vector([record.get(name)], 1, name)[0])


def _floats(values: FloatArray) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64)]
