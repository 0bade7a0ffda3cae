"""Recording rollouts: episodes of any envhub vector env into LeRobot datasets (v3.0 layout:
Parquet, MP4, JSON), and quick MP4s of one env.

    envs = envhub.make_vec("mujoco-ant", 16, render_mode="rgb_array")
    envs = envhub.RecordEpisodes(envs, "datasets/ant")       # any gymnasium VectorEnv
    envhub.record("mujoco-ant", 50, "datasets/ant", num_envs=16)
    envhub.recording.record_video("mujoco-ant", "ant.mp4", steps=300)

Needs `pyarrow` and `av` (PyAV): `pip install 'envhub[record]'`; not torch. The command line:
`envhub record ID --episodes N --out DIR`, `envhub run ID --video out.mp4`.
"""

from __future__ import annotations

from ._features import RENDER_KEY
from ._run import load_policy, record, record_video
from ._wrapper import RecordEpisodes
from .errors import (
    DatasetLayoutError,
    QueueFullWarning,
    RecordingError,
    RecordingUnavailableError,
    UnrecordableSpaceError,
)

__all__ = [
    "RENDER_KEY",
    "DatasetLayoutError",
    "QueueFullWarning",
    "RecordEpisodes",
    "RecordingError",
    "RecordingUnavailableError",
    "UnrecordableSpaceError",
    "load_policy",
    "record",
    "record_video",
]
