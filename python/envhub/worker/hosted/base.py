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

    A simulator that holds many envs in one object and steps them together (Isaac Lab,
    Gymnasium's `vector_entry_point` envs) implements `make_vec(env_id, config)` too: the
    worker then serves that one object as its whole batch of `config.num_envs` envs.
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

    def make_vec(self, env_id: str, config: Any) -> Any:
        """One vector env holding all `config.num_envs` envs of the worker, or None (the
        default) for one `make` per env.

        The object follows Gymnasium 1.x's `VectorEnv` contract: `num_envs` (equal to
        `config.num_envs`), `single_observation_space`, `single_action_space`,
        `reset(seed=..., options=...)` and `step(actions)` on arrays with a leading axis of
        `num_envs` (Dict observations as dicts of such arrays), batched `info` (`key` and
        `_key` mask), `close()`, optionally `render()`. It autoresets its envs itself and
        must say how in `metadata["autoreset_mode"]` (a `gymnasium.vector.AutoresetMode`):
        the worker serves it only to sessions with that mode, and fills same_step final
        observations from `info["final_obs"]`/`info["_final_obs"]`. It must apply
        `config.max_episode_steps` itself (the worker cannot wrap it in `TimeLimit`).
        """
        return None

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
