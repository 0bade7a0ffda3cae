"""The environment registry and task matching, with RoboSmith's API.

`EnvRegistry` loads RoboSmith-format YAML (plus envhub's `kwargs`, `max_episode_steps`,
`asset_path`, `adapter`); the loading, search and matching are the Rust code's, so Python
and the `envhub` CLI always agree.
"""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Union

from .. import _envhub
from ..wire.errors import NoMatchError

__all__ = ["NAMESPACE", "EnvEntry", "EnvRegistry", "MatchResult", "TaskSpec", "match_task_to_env"]

#: Gymnasium's namespace for the registry's ids (`gymnasium.make("envhub/<id>")`).
NAMESPACE = "envhub"

# A runtime alias, so written for CPython 3.9 (the package root imports this module in workers too).
PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class EnvEntry:
    """One environment of the registry; the YAML fields are attributes."""

    id: str
    name: str
    framework: str
    env_id: str
    robot_type: str
    env_type: str
    robot_model: str = ""
    task_tags: list[str] = field(default_factory=list)
    obs_type: str = "state"
    action_type: str = "continuous"
    description: str = ""
    source: str = ""
    kwargs: dict[str, Any] = field(default_factory=dict)
    max_episode_steps: int | None = None
    asset_path: str | None = None
    adapter: str | None = None
    # The Python environment (`python_envs:` of the registry) its workers run in, if its own.
    python_env: str | None = None
    # The registry this entry came from, so `make_env(entry)` finds it again.
    _registry: Any = field(default=None, repr=False, compare=False)

    @classmethod
    def _from_dict(cls, data: dict[str, Any], registry: Any = None) -> EnvEntry:
        return cls(**data, _registry=registry)

    def to_dict(self) -> dict[str, Any]:
        """The entry as a dict of its YAML fields."""
        return {
            f.name: copy.deepcopy(getattr(self, f.name)) for f in fields(self) if f.name != "_registry"
        }

    def summary(self) -> str:
        """`[framework] name (env_id) — description`."""
        return f"[{self.framework}] {self.name} ({self.env_id}) — {self.description}"


class EnvRegistry:
    """A catalog of environments.

    `path` is a YAML file or a list of them, combined in order (`"@default"` names the
    built-in catalog); `None` picks the registry the usual way: `ENVHUB_REGISTRY`, then
    `envhub.yaml`, then the built-in catalog.
    """

    def __init__(self, path: PathLike | Sequence[PathLike] | None = None) -> None:
        if path is None:
            self._inner = _envhub.Registry.discover()
        else:
            paths = [path] if isinstance(path, (str, os.PathLike)) else list(path)
            self._inner = _envhub.Registry.load([os.fspath(p) for p in paths])
        self._entries = [EnvEntry._from_dict(d, self._inner) for d in json.loads(self._inner.entries_json())]
        self._by_id = {e.id: e for e in self._entries}

    def get(self, env_id: str) -> EnvEntry:
        """The entry with this id; an unknown id raises `UnknownEnvError` (a `KeyError`) that
        names the closest ids."""
        entry = self._by_id.get(env_id)
        if entry is None:
            self._inner.get_json(env_id)  # raises with suggestions
            raise AssertionError("unreachable")
        return entry

    def search(
        self,
        robot_type: str | None = None,
        env_type: str | None = None,
        framework: str | None = None,
        robot_model: str | None = None,
        action_type: str | None = None,
        tags: Sequence[str] | None = None,
    ) -> list[EnvEntry]:
        """Entries that pass every filter (case-insensitive substrings; `gym` finds
        `gymnasium`). With `tags`, only entries matching at least one, best first."""
        hits = json.loads(
            self._inner.search_json(
                robot_type=robot_type,
                env_type=env_type,
                framework=framework,
                robot_model=robot_model,
                action_type=action_type,
                tags=list(tags or []),
            )
        )
        return [self._by_id[h["entry"]["id"]] for h in hits]

    def list_all(self) -> list[EnvEntry]:
        """Every entry, in file order."""
        return list(self._entries)

    def list_ids(self) -> list[str]:
        """Every id, in file order."""
        return [e.id for e in self._entries]

    def list_frameworks(self) -> list[str]:
        """Distinct frameworks, sorted."""
        return self._inner.distinct("framework")

    def list_robot_types(self) -> list[str]:
        """Distinct robot types, sorted."""
        return self._inner.distinct("robot_type")

    def list_env_types(self) -> list[str]:
        """Distinct environment types, sorted."""
        return self._inner.distinct("env_type")

    @property
    def sources(self) -> list[str]:
        """The files this registry was built from."""
        return self._inner.sources()

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[EnvEntry]:
        return iter(self._entries)

    def __contains__(self, env_id: object) -> bool:
        return env_id in self._by_id

    def __repr__(self) -> str:
        return f"EnvRegistry({len(self)} entries from {', '.join(self.sources)})"


@dataclass
class TaskSpec:
    """What a user wants to train, in RoboSmith's terms."""

    task_description: str = ""
    robot_type: str | None = None
    environment_type: str | None = None
    environment_id: str | None = None
    framework: str | None = None
    robot_model: str | None = None


@dataclass(frozen=True)
class MatchResult:
    """The best entry for a task, its score in [0, 1], why, and the runners-up
    (`[{"id", "score", "matched_tags"}]`). A runner-up that the task's filters excluded
    although it matches clearly more task words also has `"excluded"`, which says why
    (`its robot type is `custom`, not `biped``)."""

    entry: EnvEntry
    score: float
    match_reason: str
    alternatives: list[dict[str, Any]] = field(default_factory=list)


def match_task_to_env(
    spec: TaskSpec,
    registry: EnvRegistry | None = None,
    framework: str | None = None,
    *,
    strict: bool = False,
) -> MatchResult | None:
    """The registry entry that best fits `spec`, as RoboSmith's function: `None` when no
    entry fits well enough (so ported code that checks for `None` keeps working). With
    `strict=True`, raise `NoMatchError` (a `LookupError`) instead, which says what was tried
    and which robot and environment types exist. `framework` restricts the search."""
    registry = registry if registry is not None else EnvRegistry()
    query = asdict(spec)
    if framework is not None:
        query["framework"] = framework
    try:
        found = json.loads(registry._inner.match_task_json(json.dumps(query)))
    except NoMatchError:
        if strict:
            raise
        return None
    return MatchResult(
        entry=registry.get(found["entry"]["id"]),
        score=float(found["score"]),
        match_reason=found["reason"],
        alternatives=found["alternatives"],
    )
