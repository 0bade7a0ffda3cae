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
from ._factory import make, make_env, make_vec
from .adapters import AdapterRegistry, EnvAdapter
from .async_vector import AsyncVectorEnv
from .config import EnvConfig
from .env import Env
from .errors import (
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
from .recording import RecordEpisodes, record
from .registration import register_envs
from .registry import EnvEntry, EnvRegistry, MatchResult, TaskSpec, match_task_to_env
from .vector import VectorEnv

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
    "RecordEpisodes",
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
