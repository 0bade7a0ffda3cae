"""Python-hosted adapters: simulators that only exist in Python, run in `envhub.worker`
processes behind the same shared-memory data plane as the native ones.

An adapter is an `EnvAdapter` subclass. The built-in ones are listed in `BUILTIN` (adding one
is one file plus one line there); user adapters come from `ENVHUB_ADAPTERS` (import paths
`module:Class`, or `pickle:/path` for a class `register` pickled, comma-separated), which
the hub fills from its config's `adapters:` and which `envhub.AdapterRegistry().register`
extends for the current process and its workers.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from typing import Any

from .base import EnvAdapter, missing_modules
from .dm_control import DmControlAdapter
from .env_fns import EnvFnsAdapter
from .gymnasium_adapter import GymnasiumAdapter
from .isaac_lab import IsaacLabAdapter
from .lerobot_libero import LeRobotLiberoAdapter
from .lerobot_metaworld import LeRobotMetaWorldAdapter
from .libero import LiberoAdapter
from .maniskill import ManiSkillAdapter
from .metaworld import MetaWorldAdapter
from .myosuite import MyoSuiteAdapter
from .robosuite import RobosuiteAdapter

__all__ = ["BUILTIN", "PICKLED", "EnvAdapter", "all_adapters", "load_adapter_class", "missing_modules"]

#: The adapters shipped with envhub, in one explicit list.
BUILTIN: list[type[EnvAdapter]] = [
    GymnasiumAdapter,
    ManiSkillAdapter,
    LiberoAdapter,
    IsaacLabAdapter,
    MetaWorldAdapter,
    RobosuiteAdapter,
    DmControlAdapter,
    MyoSuiteAdapter,
    LeRobotLiberoAdapter,
    LeRobotMetaWorldAdapter,
    EnvFnsAdapter,
]

ADAPTERS_VAR = "ENVHUB_ADAPTERS"


#: Prefix of an `ENVHUB_ADAPTERS` entry that names a file holding a pickled adapter class (a
#: class of `__main__` or of a function, which workers cannot import by path).
PICKLED = "pickle:"


def load_adapter_class(path: str) -> type[EnvAdapter]:
    """The class an import path (`package.module:Class`) names, or the one pickled in the
    file a `pickle:/path` entry names."""
    if path.startswith(PICKLED):
        import pickle

        with open(path[len(PICKLED) :], "rb") as f:
            loaded = pickle.load(f)
        if not (isinstance(loaded, type) and issubclass(loaded, EnvAdapter)):
            raise TypeError(f"`{path}` does not hold an `envhub.EnvAdapter` subclass")
        return loaded
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"invalid adapter import path `{path}`; expected `package.module:ClassName`")
    obj: Any = importlib.import_module(module_name)
    for part in attr.split("."):
        obj = getattr(obj, part)
    if not (isinstance(obj, type) and issubclass(obj, EnvAdapter)):
        raise TypeError(f"`{path}` is not an `envhub.EnvAdapter` subclass")
    return obj


def user_adapter_paths() -> list[str]:
    """Import paths from `ENVHUB_ADAPTERS`, in order, without duplicates."""
    out: list[str] = []
    for p in os.environ.get(ADAPTERS_VAR, "").split(","):
        p = p.strip()
        if p and p not in out:
            out.append(p)
    return out


def all_adapters() -> list[tuple[EnvAdapter | None, str, str | None]]:
    """Every adapter as `(instance, name_or_path, load_error)`; a user adapter that fails to
    import is reported with its error instead of an instance."""
    out: list[tuple[EnvAdapter | None, str, str | None]] = [(cls(), cls.name, None) for cls in BUILTIN]
    for path in user_adapter_paths():
        try:
            cls = load_adapter_class(path)
            out.append((cls(), cls.name, None))
        except Exception as e:
            out.append((None, path, f"{type(e).__name__}: {e}"))
    return out
