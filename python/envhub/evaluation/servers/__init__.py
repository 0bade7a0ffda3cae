"""Policies served over the network, spoken in the protocols people already serve their
models with, so a server written for either works with envhub unchanged:

- `VlaEvalPolicy`: vla-eval's model-server protocol (`vla-eval` on PyPI).
- `OpenPIPolicy`: OpenPI's policy-server protocol (`openpi-client` on PyPI).
- `LeRobotPolicy`: LeRobot 0.6.1's async-inference policy server (gRPC; needs `grpcio`).

The first two open one WebSocket per env slot, send a batch's requests together, bound every wait by
`timeout`, and fail an episode (a `PolicyError` naming what was expected) when its server
disconnects, stalls or answers something that is not an action; the slot reconnects for its
next episode.
"""

from __future__ import annotations

from typing import Any

# The protocols by name (`envhub eval --server-protocol NAME`): module and class, imported
# when used (`servers.layout` is read by the catalog's checks without the clients' packages).
PROTOCOLS = {
    "vla-eval": ("vla_eval", "VlaEvalPolicy"),
    "openpi": ("openpi", "OpenPIPolicy"),
    "lerobot": ("lerobot", "LeRobotPolicy"),
}


def connect(protocol: str, url: str, **options: Any):
    """The Policy for a server speaking `protocol` (`vla-eval`, `openpi` or `lerobot`) at `url`."""
    import importlib

    try:
        module, name = PROTOCOLS[protocol]
    except KeyError:
        raise ValueError(f"unknown policy-server protocol {protocol!r}; valid: {sorted(PROTOCOLS)}") from None
    return getattr(importlib.import_module(f".{module}", __name__), name)(url, **options)


def __getattr__(name: str) -> Any:
    for module, cls in PROTOCOLS.values():
        if name == cls:
            import importlib

            return getattr(importlib.import_module(f".{module}", __name__), name)
    raise AttributeError(name)


__all__ = ["LeRobotPolicy", "OpenPIPolicy", "PROTOCOLS", "VlaEvalPolicy", "connect"]
