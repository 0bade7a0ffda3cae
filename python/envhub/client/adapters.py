"""`AdapterRegistry`: which simulator adapters exist and whether they can run here."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from .. import _envhub
from ..worker.hosted import ADAPTERS_VAR, PICKLED, EnvAdapter, user_adapter_paths

__all__ = ["AdapterRegistry", "EnvAdapter"]

# This process's pickled adapter classes: a private folder, removed at exit.
_PICKLED_DIR: str | None = None


def _pickle_class(cls: type) -> str:
    """Cloudpickles `cls` (by value) into this process's private folder; the
    `ENVHUB_ADAPTERS` entry naming it. Registering the class again rewrites its file."""
    global _PICKLED_DIR
    import atexit
    import shutil
    import tempfile

    import cloudpickle

    if _PICKLED_DIR is None:
        _PICKLED_DIR = tempfile.mkdtemp(prefix="envhub-adapters-")  # mode 0700
        atexit.register(shutil.rmtree, _PICKLED_DIR, True)
    safe = "".join(c if c.isalnum() else "_" for c in f"{cls.name}_{cls.__qualname__}")
    file = os.path.join(_PICKLED_DIR, f"{safe}.pkl")
    try:
        data = cloudpickle.dumps(cls)
    except Exception as e:
        raise TypeError(
            f"adapter `{cls.name}` ({cls.__qualname__}) cannot be pickled for the workers: {type(e).__name__}: {e}\n"
            "hint: move the class into a module (`my_sim.py`) and import it from there"
        ) from e
    with open(file + ".tmp", "wb") as f:
        f.write(data)
    os.replace(file + ".tmp", file)
    return f"{PICKLED}{file}"


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
        `PYTHONPATH`, so the daemon routes to it and its workers load it too.

        Workers import a class of an importable module by its import path. A class they
        cannot import (defined in the running script, `__main__`, or in a function) is
        cloudpickled by value into a private file that lives as long as this process. For a
        permanent registration list `module:Class` under `adapters:` in `envhub.yaml`."""
        cls = adapter if isinstance(adapter, type) else type(adapter)
        if not (isinstance(cls, type) and issubclass(cls, EnvAdapter)):
            raise TypeError(f"{adapter!r} is not an `envhub.EnvAdapter` subclass")
        if not cls.name:
            raise ValueError(f"adapter class `{cls.__qualname__}` has no `name`")
        by_value = cls.__module__ == "__main__" or "<locals>" in cls.__qualname__
        path = _pickle_class(cls) if by_value else f"{cls.__module__}:{cls.__qualname__}"
        paths = user_adapter_paths()
        if path not in paths:
            os.environ[ADAPTERS_VAR] = ",".join([*paths, path])
        # Workers find the module (for `__main__`, the script's folder, whose modules a
        # pickled class may use) where this process found it.
        module = sys.modules[cls.__module__]
        file = getattr(module, "__file__", None)
        if file:
            root = Path(file).resolve().parent
            if not by_value:
                for _ in range(cls.__module__.count(".") + (1 if Path(file).name == "__init__.py" else 0)):
                    root = root.parent
            entries = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
            if str(root) not in entries:
                os.environ["PYTHONPATH"] = os.pathsep.join([str(root), *entries])
        _envhub.refresh_adapters()
        self._adapters = json.loads(_envhub.adapters_json())

    def __repr__(self) -> str:
        return f"AdapterRegistry(available={self.list_available()})"
