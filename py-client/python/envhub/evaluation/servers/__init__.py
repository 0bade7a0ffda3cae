"""Policies served over the network, spoken in the protocols people already serve their
models with, so a server written for either works with envhub unchanged:

- `VlaEvalPolicy`: vla-eval's model-server protocol (`vla-eval` on PyPI).
- `OpenPIPolicy`: OpenPI's policy-server protocol (`openpi-client` on PyPI).

Both open one WebSocket per env slot, send a batch's requests together, bound every wait by
`timeout`, and fail an episode (a `PolicyError` naming what was expected) when its server
disconnects, stalls or answers something that is not an action; the slot reconnects for its
next episode.
"""

from __future__ import annotations

from typing import Any

from .openpi import OpenPIPolicy
from .vla_eval import VlaEvalPolicy

# The protocols by name, as `envhub eval --policy <name>://host:port` spells them.
PROTOCOLS = {"vla-eval": VlaEvalPolicy, "openpi": OpenPIPolicy}


def connect(protocol: str, url: str, **options: Any):
    """The Policy for a server speaking `protocol` (`vla-eval` or `openpi`) at `url`."""
    try:
        cls = PROTOCOLS[protocol]
    except KeyError:
        raise ValueError(f"unknown policy-server protocol {protocol!r}; valid: {sorted(PROTOCOLS)}") from None
    return cls(url, **options)


__all__ = ["OpenPIPolicy", "PROTOCOLS", "VlaEvalPolicy", "connect"]
