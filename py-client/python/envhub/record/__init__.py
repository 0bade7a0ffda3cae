"""Recording rollouts: LeRobot v3 datasets (`RecordEpisodes`, `record`) and MP4 videos
(`record_video`). Needs `pyarrow` and `av` (PyAV), not torch."""

from __future__ import annotations

from ._layout import DatasetWriter, LayoutError
from ._run import record, record_video, task_of
from ._wrapper import RecordEpisodes

__all__ = ["DatasetWriter", "LayoutError", "RecordEpisodes", "record", "record_video", "task_of"]
