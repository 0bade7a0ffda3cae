"""What the suite adapters (Meta-World, dm_control, MyoSuite, robosuite) share: the check
that this interpreter has the MuJoCo a suite runs on, and infos that travel whole.

Each suite pins its own MuJoCo (Meta-World and robosuite 3.3, dm_control 3.17, MyoSuite
4.0), so each runs in a Python environment of its own, declared in the catalog
(`python_envs:` in `configs/env_registry.yaml`); the hub starts the suite's workers in that
environment's interpreter.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any, ClassVar

from .base import EnvAdapter


def installed_version(dist: str) -> str | None:
    """The installed version of the distribution `dist`, or None."""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


class SuiteAdapter(EnvAdapter):
    """An adapter for a suite that runs on one MuJoCo series (`mujoco_series`, version
    prefixes such as `"3.3."`): in another it is unavailable, with the reason and the catalog's
    Python environment as the fix (each suite's pins fight the others')."""

    mujoco_series: ClassVar[tuple[str, ...]] = ()
    #: The `python_envs:` entry of the default catalog this suite runs in.
    python_env: ClassVar[str] = ""

    def availability(self) -> tuple[bool, str | None, str | None]:
        ok, reason, hint = super().availability()
        if not ok:
            return ok, reason, hint
        if self.mujoco_series:
            got = installed_version("mujoco")
            if got is None or not got.startswith(self.mujoco_series):
                want = " or ".join(f"{s}x" for s in self.mujoco_series)
                return (
                    False,
                    f"{self.name} runs on mujoco {want}; this interpreter has mujoco {got}",
                    (
                        f"run it in the catalog's Python environment `{self.python_env}` (`envhub env sync "
                        f"{self.python_env}`), or install the requirements listed there into an interpreter of its own"
                    ),
                )
        return True, None, None


def gym_make(env_id: str, config: Any, kwargs: dict[str, Any]) -> Any:
    """`gymnasium.make` with the session's render mode and step limit (0 or None: the id's
    own)."""
    import gymnasium as gym

    limit = config.max_episode_steps or None
    return gym.make(env_id, render_mode=config.render_mode, max_episode_steps=limit, **kwargs)


def unknown_id(suite: str, env_id: str, ids: list[str], hint: str) -> LookupError:
    """The error for an id the suite does not register, with the closest ones."""
    from difflib import get_close_matches

    close = get_close_matches(env_id, ids, n=3, cutoff=0.5)
    guess = f"; did you mean {' or '.join(f'`{c}`' for c in close)}?" if close else ""
    return LookupError(f"{suite} has no env `{env_id}`{guess}\nhint: {hint}")
