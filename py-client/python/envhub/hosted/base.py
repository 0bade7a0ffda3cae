"""`EnvAdapter`: the contract a Python-hosted adapter implements (RoboSmith's, plus
availability with an install hint)."""

from __future__ import annotations

import importlib.util
from typing import Any, ClassVar


def missing_modules(modules: list[str]) -> list[str]:
    """The modules of `modules` that cannot be imported here (checked without importing)."""
    missing = []
    for m in modules:
        try:
            if importlib.util.find_spec(m) is None:
                missing.append(m)
        except (ImportError, ValueError):
            missing.append(m)
    return missing


class EnvAdapter:
    """A simulator family hosted in a Python worker.

    Subclass it and set `name`, `frameworks` (registry entries with one of these
    `framework:` values route here), `requires` (importable module names), `description`
    and `install_hint`; implement `make(env_id, config)`, which returns an object with the
    Gymnasium contract (`reset`, `step`, `observation_space`, `action_space`, `close`), and
    optionally `list_envs()` (ids it implements; empty: it takes any id of its frameworks).
    Override `availability()` when a module check is not enough (a GPU, a licence).
    """

    name: ClassVar[str] = ""
    frameworks: ClassVar[list[str]] = []
    requires: ClassVar[list[str]] = []
    description: ClassVar[str] = ""
    install_hint: ClassVar[str] = ""

    def availability(self) -> tuple[bool, str | None, str | None]:
        """`(True, None, None)`, or `(False, reason, hint)` saying what is missing and how to
        install it."""
        missing = missing_modules(list(self.requires))
        if not missing:
            return True, None, None
        hint = self.install_hint or f"pip install {' '.join(missing)}"
        names = ", ".join(f"`{m}`" for m in missing)
        return False, f"Python module {names} is not installed (interpreter: {_python()})", hint

    def make(self, env_id: str, config: Any) -> Any:
        """A new env (Gymnasium contract) for `env_id`, configured by `config`
        (`envhub.EnvConfig`)."""
        raise NotImplementedError(f"adapter `{self.name}` does not implement make()")

    def list_envs(self) -> list[str]:
        """Env ids this adapter implements (empty: any id of its frameworks)."""
        return []

    def describe(self) -> dict[str, Any]:
        """The adapter as the hub's catalog reads it."""
        ok, reason, hint = self.availability()
        availability: dict[str, Any] = {"status": "available"}
        if not ok:
            availability = {"status": "unavailable", "reason": reason or "unavailable", "hint": hint or ""}
        return {
            "name": self.name,
            "frameworks": [f.lower() for f in self.frameworks],
            "requires": list(self.requires),
            "description": self.description,
            "availability": availability,
            "envs": list(self.list_envs()) if ok else [],
        }


def _python() -> str:
    import sys

    return sys.executable
