"""The recorder's errors (all `envhub.EnvHubError`s) and its warning."""

from __future__ import annotations

from ..wire.errors import EnvHubError

__all__ = [
    "DatasetLayoutError",
    "QueueFullWarning",
    "RecordingError",
    "RecordingUnavailableError",
    "UnrecordableSpaceError",
]


class DatasetLayoutError(EnvHubError, ValueError):
    """The folder holds a dataset of another layout (version, fps, features) than the one being
    recorded; the message names each difference."""


class UnrecordableSpaceError(EnvHubError, ValueError):
    """An observation or action space has no LeRobot feature (Tuple, Text, Graph)."""


class RecordingError(EnvHubError, RuntimeError):
    """The writer failed (the cause is chained), or the dataset is being written by another
    recorder."""


class RecordingUnavailableError(EnvHubError, ImportError):
    """`pyarrow` or `av` (PyAV) is not installed: `pip install 'envhub[record]'`."""


class QueueFullWarning(UserWarning):
    """The writer fell behind the steps: its queue was full, so steps waited or frames were
    dropped (`RecordEpisodes(when_full=...)`)."""


def require() -> None:
    """Raises `RecordingUnavailableError` unless pyarrow and PyAV import."""
    missing = []
    for module, package in (("pyarrow", "pyarrow"), ("av", "av")):
        try:
            __import__(module)
        except ImportError:
            missing.append(package)
    if missing:
        raise RecordingUnavailableError(
            f"recording needs {' and '.join(f'`{m}`' for m in missing)}, which are not installed\n"
            "hint: pip install 'envhub[record]'"
        )
