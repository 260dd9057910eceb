"""An ego under test in another process, over ZeroMQ (``ego: {policy: external}``).

* :mod:`~avrisk.agents.external.protocol` -- the versioned wire format and its
  checked parsing (``docs/ego-protocol.md``);
* :mod:`~avrisk.agents.external.spaces` -- what the AV observes and commands;
* :mod:`~avrisk.agents.external.client` -- :class:`ExternalEgo`, the actor that
  asks the AV for the ego's actions, batch by batch;
* :mod:`~avrisk.agents.external.server` -- a reference AV process in Python
  (``avrisk serve-ego``), driving :class:`AccController`.

pyzmq and msgpack are the optional extra ``avrisk[external]``: this package
registers the policy without importing them.
"""

from __future__ import annotations

from typing import Any

from avrisk.agents.external.params import ExternalParams
from avrisk.agents.policy import register_policy

__all__ = ["EXTERNAL", "ExternalParams"]

#: The registered name of the external ego policy.
EXTERNAL = "external"


def _external_factory(*, n_vehicles: int, device: Any, **offered: Any) -> Any:
    """The client (imported only now: it needs the extra), from validated params."""
    from avrisk.agents.external.client import ExternalEgo

    fields = ExternalParams.model_fields
    params = ExternalParams(**{k: v for k, v in offered.items() if k in fields})
    return ExternalEgo(n_vehicles, params, device=device)


register_policy(EXTERNAL, _external_factory, params=ExternalParams)
