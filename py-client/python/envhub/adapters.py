"""`AdapterRegistry`: which simulator adapters exist and whether they can run here."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from . import _envhub
from .hosted import ADAPTERS_VAR, EnvAdapter, user_adapter_paths

__all__ = ["AdapterRegistry", "EnvAdapter"]


class AdapterRegistry:
    """The adapters the workers host (native in `envhub-worker`, Python-hosted in
    `python -m envhub.worker`), with their availability (asked once per process)."""

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
                    "host": a.get("host", "native"),
                }
            )
        return out

    def get(self, name: str) -> dict[str, Any]:
        """One adapter's description (as in `list_all`); `KeyError` if there is none."""
        for a in self.list_all():
            if a["name"] == name:
                return a
        raise KeyError(f"no adapter `{name}`; adapters: {', '.join(a['name'] for a in self._adapters)}")

    def register(self, adapter: type[EnvAdapter] | EnvAdapter) -> None:
        """Registers a Python adapter (an `envhub.EnvAdapter` subclass) for this process and
        the workers it starts: registry entries with one of its `frameworks` route to it.
        With a hub daemon (`ENVHUB_HUB`), each request carries this process's adapters and
        `PYTHONPATH`, so the daemon routes to it and its workers import it too.

        Workers import the class by its import path, so it must live in an importable module
        (not `__main__`). For a permanent registration list `module:Class` under `adapters:`
        in `envhub.yaml`."""
        cls = adapter if isinstance(adapter, type) else type(adapter)
        if not (isinstance(cls, type) and issubclass(cls, EnvAdapter)):
            raise TypeError(f"{adapter!r} is not an `envhub.EnvAdapter` subclass")
        if not cls.name:
            raise ValueError(f"adapter class `{cls.__qualname__}` has no `name`")
        if cls.__module__ == "__main__" or "<locals>" in cls.__qualname__:
            raise ValueError(
                f"adapter `{cls.name}` is defined in `__main__` or a function; workers import it by path\n"
                "hint: move the class into a module (`my_sim.py`) and import it from there"
            )
        path = f"{cls.__module__}:{cls.__qualname__}"
        paths = user_adapter_paths()
        if path not in paths:
            os.environ[ADAPTERS_VAR] = ",".join([*paths, path])
        # Workers find the module where this process found it.
        module = sys.modules[cls.__module__]
        file = getattr(module, "__file__", None)
        if file:
            root = Path(file).resolve().parent
            for _ in range(cls.__module__.count(".") + (1 if Path(file).name == "__init__.py" else 0)):
                root = root.parent
            entries = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
            if str(root) not in entries:
                os.environ["PYTHONPATH"] = os.pathsep.join([str(root), *entries])
        _envhub.refresh_adapters()
        self._adapters = json.loads(_envhub.adapters_json())

    def __repr__(self) -> str:
        return f"AdapterRegistry(available={self.list_available()})"
