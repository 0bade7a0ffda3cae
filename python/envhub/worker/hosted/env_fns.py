"""`env_fns`: the envs of `envhub.AsyncVectorEnv`, built from the user's own factories.

The client cloudpickles its list of env factories (lambdas, closures, classes of `__main__`
included, as Gymnasium's `AsyncVectorEnv` does) into a payload file and names that file as
the env id; each worker loads it once and builds env `i` of the session with factory `i`
(`config.env_index`). Each env is wrapped so that infos and reset options travel whole
(`envhub._pickled`, or plain JSON where that is exact) and actions reach it as Gymnasium's
`AsyncVectorEnv` hands them over;
autoreset is the serve loop's, which follows Gymnasium 1.x's.
"""

from __future__ import annotations

import os
import pickle
import sys
from typing import Any

import numpy as np

from ...wire import calls as _calls
from ...wire.pickled import unwrap
from .base import EnvAdapter

#: Registry framework (and adapter name) of a drop-in session.
FRAMEWORK = "env_fns"

# Payloads already loaded by this worker, by path: a worker's envs share one load.
_LOADED: dict[str, list[Any]] = {}
_CALLS: dict[str, tuple[str, bytes] | None] = {}


def write_payload(path: str, env_fns_pickle: bytes, calls: tuple[str, bytes] | None = None) -> None:
    """Writes the payload a worker reads: the client's `sys.path` (so factories pickled by
    reference, such as classes of the training script's own modules, import in the worker as
    in the client, like multiprocessing's spawn does), the cloudpickled factories, and where
    to answer `call`s (`envhub._calls`: a folder and an auth key)."""
    payload = {
        "sys_path": [p for p in sys.path if isinstance(p, str)],
        "env_fns": env_fns_pickle,
        "calls": calls,
    }
    with open(path, "wb") as f:
        pickle.dump(payload, f, protocol=pickle.HIGHEST_PROTOCOL)


def load_factories(path: str) -> list[Any]:
    """The factories of a payload file (loaded once per process)."""
    if path not in _LOADED:
        if not os.path.isfile(path):
            raise FileNotFoundError(
                f"env factories file `{path}` does not exist; it lives only while "
                "`envhub.AsyncVectorEnv` starts its workers\nhint: make envs of framework "
                f"`{FRAMEWORK}` only through `envhub.AsyncVectorEnv(env_fns)`"
            )
        with open(path, "rb") as f:
            payload = pickle.load(f)
        _CALLS[path] = payload.get("calls")
        for p in payload["sys_path"]:
            if p not in sys.path:
                sys.path.append(p)
        try:
            _LOADED[path] = list(pickle.loads(payload["env_fns"]))
        except Exception as e:
            raise RuntimeError(
                f"cannot unpickle the env factories in the worker ({type(e).__name__}: {e})\n"
                "hint: a factory pickled by reference needs its module importable in the worker "
                "(on the client's sys.path or PYTHONPATH)"
            ) from e
    return _LOADED[path]


class EnvFnsAdapter(EnvAdapter):
    """Envs built by user factories (`envhub.AsyncVectorEnv`); the env id is the payload
    file."""

    name = FRAMEWORK
    frameworks = [FRAMEWORK]
    requires = ["gymnasium", "cloudpickle"]
    description = "envs from user factories, for envhub.AsyncVectorEnv (Gymnasium's drop-in)"
    install_hint = "pip install gymnasium cloudpickle"

    def make(self, env_id: str, config: Any) -> Any:
        factories = load_factories(env_id)
        i = config.env_index
        if i is None or not 0 <= i < len(factories):
            raise IndexError(f"env index {i} is outside the {len(factories)} env factories of `{env_id}`")
        try:
            env = factories[i]()
        except Exception as e:
            raise RuntimeError(f"env factory {i} ({_describe(factories[i])}) raised {type(e).__name__}: {e}") from e
        calls = _CALLS.get(env_id)
        if calls is not None:
            _calls.serve(*calls, i, env)
        return DropInEnv(env)


def _describe(fn: Any) -> str:
    return getattr(fn, "__qualname__", None) or type(fn).__name__


class DropInEnv:
    """One user env as Gymnasium's `AsyncVectorEnv` worker drives it: a Discrete action
    arrives as a numpy scalar (not a 0-d array), options travel pickled. Its infos are
    `exact_infos`: the worker delivers them exactly (typed columns where they fit, else
    `envhub._pickled.encode_info`)."""

    exact_infos = True

    def __init__(self, env: Any) -> None:
        self.env = env
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        self.metadata = getattr(env, "metadata", {})
        self.spec = getattr(env, "spec", None)
        self.render_mode = getattr(env, "render_mode", None)

    def reset(self, seed: int | None = None, options: Any = None) -> Any:
        return self.env.reset(seed=seed, options=unwrap(options))

    def step(self, action: Any) -> Any:
        if isinstance(action, np.ndarray) and action.ndim == 0:
            action = action[()]
        return self.env.step(action)

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()
