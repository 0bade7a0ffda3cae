"""envhub: Gymnasium environments in worker processes, observations through shared memory.

    import envhub
    env = envhub.make("gym-cartpole")                     # a gymnasium.Env
    envs = envhub.make_vec("gym-cartpole", num_envs=64)   # a gymnasium.vector.VectorEnv
    env = gymnasium.make("envhub/gym-cartpole")           # after `import envhub`
    envs = envhub.AsyncVectorEnv([lambda: MyEnv()] * 8)   # gymnasium's AsyncVectorEnv, on envhub
    envs = envhub.RecordEpisodes(envs, "datasets/run1")    # episodes into a LeRobot dataset
    venv = envhub.sb3.make_vec("mujoco-ant", 8)           # Stable-Baselines3's VecEnv (import envhub.sb3)

Observations are read-only numpy arrays that view the worker's shared memory; the simulator
runs in an `envhub-worker` process, so a crash there raises `WorkerDiedError` here instead of
taking the training process down. Registry, task matching and adapters follow RoboSmith's
API (`EnvRegistry`, `TaskSpec`, `match_task_to_env`, `EnvConfig`, `make_env`,
`AdapterRegistry`).
"""

from __future__ import annotations

import sys
from pathlib import Path

from . import _envhub
from .registration import register_envs
from .wire.errors import (
    AdapterUnavailableError,
    DataPlaneError,
    EnvFailedError,
    EnvHubError,
    ForkError,
    HubDaemonError,
    HubLostError,
    HubRefusedError,
    InvalidActionError,
    InvalidConfigError,
    InvalidStateError,
    MakeError,
    NetworkError,
    NoAdapterError,
    NoMatchError,
    RegistryError,
    UnknownEnvError,
    UnknownHubError,
    WorkerBinaryError,
    WorkerDiedError,
)

# The rest of the public API is imported on first use (PEP 562), so a worker process, which
# imports this package before `envhub.worker`, loads no client or integration code: the
# worker side must run on what each suite pins (see `envhub.worker`).
_LAZY = {
    "make": "client.factory",
    "make_env": "client.factory",
    "make_vec": "client.factory",
    "AdapterRegistry": "client.adapters",
    "EnvAdapter": "worker.hosted.base",
    "AsyncVectorEnv": "client.async_vector",
    "EnvConfig": "wire.config",
    "Env": "client.env",
    "VectorEnv": "client.vector",
    "EnvEntry": "client.registry",
    "EnvRegistry": "client.registry",
    "MatchResult": "client.registry",
    "TaskSpec": "client.registry",
    "match_task_to_env": "client.registry",
    "RecordEpisodes": "recording",
    "record": "recording",
    "evaluate": "evaluation",
}
# Subpackages reached as attributes (`envhub.sb3.make_vec`, `envhub.recording.RecordingError`).
_SUBMODULES = frozenset({"sb3", "recording", "evaluation", "worker", "client", "wire", "errors"})


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    elif name == "eval":
        value = importlib.import_module(".evaluation", __name__).evaluate
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'envhub' has no attribute '{name}'")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | {"eval"} | _SUBMODULES)


__version__: str = _envhub.__version__

# The worker binary `make py-install` puts beside this package (`ENVHUB_WORKER` overrides it).
_envhub.set_worker_binary(str(Path(__file__).resolve().parent / "bin" / "envhub-worker"))
# Python-hosted adapters run in this interpreter unless ENVHUB_PYTHON or the config names one.
_envhub.set_python(sys.executable)


def hubs() -> list[dict]:
    """The live hubs on the network (`envhub serve` on other machines), each a dict with
    `name`, `host`, `cores`, `version`, `adapters`, `catalog`, `envs`, `workers`,
    `sessions`, `load`. The network is reached as `envhub.yaml`'s `zenoh:` section and
    `ENVHUB_CONNECT` say (multicast scouting by default); waits briefly for discovery on
    first use."""
    import json

    return json.loads(_envhub.hubs_json())


def worker_binary() -> str:
    """The `envhub-worker` binary sessions start."""
    return str(_envhub.worker_binary())


try:
    register_envs()
except EnvHubError as _e:  # a broken registry file must not make `import envhub` fail
    import warnings

    warnings.warn(f"envhub: gymnasium ids not registered: {_e}", stacklevel=1)

__all__ = [
    "AdapterRegistry",
    "AdapterUnavailableError",
    "AsyncVectorEnv",
    "DataPlaneError",
    "Env",
    "EnvAdapter",
    "EnvConfig",
    "EnvEntry",
    "EnvFailedError",
    "EnvHubError",
    "EnvRegistry",
    "ForkError",
    "HubDaemonError",
    "HubLostError",
    "HubRefusedError",
    "NetworkError",
    "UnknownHubError",
    "InvalidActionError",
    "InvalidConfigError",
    "InvalidStateError",
    "MakeError",
    "MatchResult",
    "NoAdapterError",
    "NoMatchError",
    "RecordEpisodes",
    "RegistryError",
    "TaskSpec",
    "UnknownEnvError",
    "VectorEnv",
    "WorkerBinaryError",
    "WorkerDiedError",
    "make",
    "make_env",
    "hubs",
    "make_vec",
    "match_task_to_env",
    "record",
    "register_envs",
    "worker_binary",
]
