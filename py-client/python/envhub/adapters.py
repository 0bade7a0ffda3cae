"""`AdapterRegistry`: which simulator adapters exist and whether they can run here."""

from __future__ import annotations

import json
from typing import Any

from . import _envhub

__all__ = ["AdapterRegistry"]


class AdapterRegistry:
    """The adapters the worker binary hosts, with their availability (asked once per process)."""

    def __init__(self) -> None:
        self._adapters: list[dict[str, Any]] = json.loads(_envhub.adapters_json())

    def list_available(self) -> list[str]:
        """Names of the adapters that can run here."""
        return [a["name"] for a in self._adapters if a["availability"]["status"] == "available"]

    def list_all(self) -> list[dict[str, Any]]:
        """Every adapter: `name`, `frameworks`, `available`, `requires`, `description`, and
        for an unavailable one the `reason` and the install `hint`; `envs` lists the env ids
        it implements natively (empty: it forwards any id to its framework)."""
        out = []
        for a in self._adapters:
            availability = a["availability"]
            out.append(
                {
                    "name": a["name"],
                    "frameworks": list(a["frameworks"]),
                    "available": availability["status"] == "available",
                    "requires": list(a["requires"]),
                    "description": a["description"],
                    "reason": availability.get("reason"),
                    "hint": availability.get("hint"),
                    "envs": list(a["envs"]),
                }
            )
        return out

    def get(self, name: str) -> dict[str, Any]:
        """One adapter's description (as in `list_all`); `KeyError` if there is none."""
        for a in self.list_all():
            if a["name"] == name:
                return a
        raise KeyError(f"no adapter `{name}`; adapters: {', '.join(a['name'] for a in self._adapters)}")

    def register(self, adapter: Any) -> None:
        """Registering Python adapters comes with Python-hosted workers."""
        raise NotImplementedError(
            "registering Python adapters is not supported yet; "
            "native adapters are listed in adapters/worker/src/adapters.rs"
        )

    def __repr__(self) -> str:
        return f"AdapterRegistry(available={self.list_available()})"
