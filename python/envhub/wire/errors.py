"""envhub's exceptions: one class per kind of error, all deriving from `EnvHubError`.

Each also derives from the builtin exception a caller would naturally catch, so code written
for Gymnasium keeps working: an unknown id is a `KeyError`, a bad action a `ValueError`, a
missing simulator an `ImportError`. Messages say what was wrong and end with a `hint:` line.
"""

from __future__ import annotations

__all__ = [
    "EnvHubError",
    "UnknownEnvError",
    "RegistryError",
    "NoMatchError",
    "NoAdapterError",
    "AdapterUnavailableError",
    "InvalidConfigError",
    "MakeError",
    "InvalidActionError",
    "InvalidStateError",
    "ForkError",
    "WorkerDiedError",
    "EnvFailedError",
    "WorkerBinaryError",
    "DataPlaneError",
    "HubDaemonError",
    "NetworkError",
    "HubLostError",
    "UnknownHubError",
    "HubRefusedError",
]


class EnvHubError(Exception):
    """Base class of every envhub error."""


class UnknownEnvError(EnvHubError, KeyError):
    """No registry entry has this id. `suggestions` lists the closest ids."""

    env_id: str = ""
    suggestions: list[str] = []

    def __str__(self) -> str:  # KeyError would show the message quoted
        return str(self.args[0]) if self.args else ""


class RegistryError(EnvHubError, ValueError):
    """A registry file could not be read or is malformed (the message names file and line)."""


class NoMatchError(EnvHubError, LookupError):
    """No registry entry fits a task description."""


class NoAdapterError(EnvHubError, LookupError):
    """No adapter runs the entry's framework or env id."""


class AdapterUnavailableError(EnvHubError, ImportError):
    """The adapter exists but cannot run here; `reason` says what is missing, `hint` how to fix it."""

    adapter: str = ""
    reason: str = ""
    hint: str = ""


class InvalidConfigError(EnvHubError, ValueError):
    """An option of the env or the session is invalid."""


class MakeError(EnvHubError, ValueError):
    """The worker could not create the envs (an unknown option, an unsupported render mode, ...)."""


class InvalidActionError(EnvHubError, ValueError):
    """Actions of the wrong shape or dtype, discrete values out of range, NaN or infinite
    values; continuous values beyond the bounds only with `strict_actions=True`."""


class InvalidStateError(EnvHubError, RuntimeError):
    """The call is not valid now (the env is closed, not reset, or has results to `recv`)."""


class ForkError(InvalidStateError):
    """An env was used in a process forked from the one that made it."""


class WorkerDiedError(EnvHubError, RuntimeError):
    """A worker process crashed or hung; `worker`, `pid` and `envs` say which."""

    worker: int = -1
    pid: int = -1
    envs: str = ""


class EnvFailedError(EnvHubError, RuntimeError):
    """An env raised an error while resetting or stepping."""


class WorkerBinaryError(EnvHubError, OSError):
    """The `envhub-worker` binary could not be found or started."""

    def __str__(self) -> str:  # OSError would format (errno, strerror) pairs
        return str(self.args[0]) if self.args else ""


class DataPlaneError(EnvHubError, RuntimeError):
    """The shared-memory layer failed."""


class HubDaemonError(EnvHubError, ConnectionError):
    """Talking to an `envhub serve` daemon failed, or it reported an error."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class NetworkError(EnvHubError, ConnectionError):
    """Reaching other hubs over the network (Zenoh) failed."""


class HubLostError(NetworkError):
    """A remote hub went away (exited, froze past its lease, or was cut off): `hub` names it,
    `envs` the range of the session's envs it hosted."""

    hub: str = ""
    envs: str = ""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class UnknownHubError(EnvHubError, LookupError):
    """A hub named in a placement is not live; the message lists the live ones."""

    hub: str = ""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class HubRefusedError(EnvHubError, PermissionError):
    """A remote hub refused the request (its security policy or its limits)."""

    hub: str = ""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
