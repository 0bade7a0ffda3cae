"""`--record DIR`: every evaluated episode into one LeRobot dataset (v3.0, the recorder's
files and guarantees), off the stepping path.

An episode's frames are what its policy acted on: frame `t` holds the observation after
settling (`t = 0`) or after step `t - 1`, as the env gave it (before the protocol's flips or
resizing), the action the env got, and what that step returned (`next.*`). The settling
steps are not frames. The episode's last frame is `next.done`; `next.truncated` where the
protocol ended it (its horizon, or success) and the env did not. The task text is the
benchmark's (LIBERO's instruction, the catalog description), the episode's `success` the
protocol's.

The stepping side copies each observation once, when the policy is shown it, and queues
steps to one writer thread through a queue bounded in bytes (a full queue makes the step
wait). The writer encodes each camera's frames into the episode's MP4 as they come, keeps the
numeric columns (small) per episode, and commits ended episodes together at most every
`commit_every` seconds and at the end.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..recording._budget import DEFAULT_QUEUE_BYTES, ByteQueue
from ..recording._dataset import Dataset
from ..recording._dataset import Episode as Recorded
from ..recording._encoding import CANONICAL, DEFAULT_CODEC
from ..recording._features import (
    STEP_COLUMNS,
    Column,
    action_column,
    features,
    frame_rate,
    observation_columns,
)
from ..recording._video import EpisodeVideo, check_codec
from ..recording.errors import RecordingError, require

__all__ = ["EpisodeDataset"]

_STOP = ("stop",)


class _Open:
    """One slot's episode being written: its numeric rows and its cameras' encoders."""

    def __init__(self) -> None:
        self.rows: dict[str, list[np.ndarray]] = {}
        self.videos: dict[str, EpisodeVideo] = {}
        self.length = 0


class EpisodeDataset:
    """The dataset at `root` (created, or appended to with the same layout) that an
    evaluation's episodes go to. `session(envs, task)` checks each session's spaces (the first
    opens the dataset); per slot, `observe` gives the observation the policy is shown, `step`
    what the env got and returned, `finish` / `discard` end the episode. `close()` commits
    what ended and releases the folder."""

    def __init__(
        self,
        root: str | Path,
        *,
        fps: int | None = None,
        codec: str | None = None,
        crf: int | None = None,
        gop: int | None = None,
        queue_bytes: int = DEFAULT_QUEUE_BYTES,
        commit_every: float = 1.0,
    ) -> None:
        require()
        if codec is not None:
            check_codec(codec)
        if queue_bytes < 1:
            raise ValueError(f"`queue_bytes={queue_bytes}` must be at least 1 (a byte budget)")
        self.root = Path(root)
        self._fps, self._codec, self._crf, self._gop = fps, codec, crf, gop
        self._commit_every = commit_every
        self._queue = ByteQueue(queue_bytes)
        self._layout: tuple[list[Column], Column, str] | None = None  # columns, action, first task
        self._dataset: Dataset | None = None
        self._thread: threading.Thread | None = None
        self._held: dict[int, dict[str, np.ndarray]] = {}  # each slot's observation shown
        self.error: BaseException | None = None
        self.stats = {"episodes_written": 0, "episodes_discarded": 0, "frames": 0, "queue_bytes_peak": 0}

    # -- the stepping side ------------------------------------------------------------------

    def session(self, envs: Any, task: str) -> None:
        """Checks a session's observation and action spaces against the dataset's; the first
        session's open it (one dataset has one layout)."""
        columns = observation_columns(envs.single_observation_space)
        action = action_column(envs.single_action_space)
        if self._layout is None:
            fps = frame_rate(envs.metadata.get("render_fps"), self._fps)
            wanted = features([*columns, action, *STEP_COLUMNS], fps, CANONICAL[self._codec or DEFAULT_CODEC])
            # An existing dataset's own encoding (its codec, CRF, GOP), unless others are asked.
            self._dataset = Dataset(self.root, fps, wanted, None, codec=self._codec, crf=self._crf, gop=self._gop)
            self._layout = (columns, action, task)
            self._video_fps = fps
            self._thread = threading.Thread(target=self._run, name="envhub-eval-dataset", daemon=True)
            self._thread.start()
            return
        first_columns, first_action, first = self._layout
        if (columns, action) != (first_columns, first_action):

            def shape(cs: list[Column]) -> str:
                return ", ".join(f"{c.name} {c.dtype.name}{list(c.shape)}" for c in cs)

            raise RecordingError(
                f"`--record` writes one dataset, and task `{task}`'s frames differ from task `{first}`'s:\n"
                f"  {first}: {shape([*first_columns, first_action])}\n  {task}: {shape([*columns, action])}\n"
                "hint: record the tasks with the same spaces in one evaluation, the others in another"
            )

    def observe(self, slot: int, obs: Any) -> None:
        """The observation `slot`'s policy is shown (its episode's next frame): copied."""
        assert self._layout is not None
        held = {}
        for c in self._layout[0]:
            value = obs
            for key in c.path:
                value = value[key]
            held[c.name] = np.array(value, copy=True) if c.video else np.array(value, copy=True).reshape(-1)
        self._held[slot] = held

    def step(self, slot: int, action: np.ndarray, reward: float, terminated: bool) -> None:
        """`slot`'s env got `action` on the observation last given, and returned these."""
        obs = self._held.pop(slot)
        row = {**obs, "action": np.array(action, copy=True).reshape(-1)}
        row["next.reward"] = np.array([reward], dtype=np.float64)
        row["next.terminated"] = np.array([terminated])
        self._put(("row", slot, row), sum(v.nbytes for v in row.values()))

    def finish(self, slot: int, task: str, success: bool | None) -> None:
        self._held.pop(slot, None)
        self._put(("end", slot, task, success), 0)

    def discard(self, slot: int) -> None:
        self._held.pop(slot, None)
        self._put(("drop", slot), 0)

    def close(self) -> None:
        """Commits every ended episode and releases the dataset; re-raises the writer's error."""
        if self._thread is not None:
            while self._thread.is_alive() and not self._queue.put(_STOP, 0, timeout=0.5):
                pass
            self._thread.join()
            self._thread = None
        if self._dataset is not None:
            self._dataset.close()
            self._dataset = None
        self.stats["queue_bytes_peak"] = self._queue.peak
        self._check()

    def _put(self, item: tuple, nbytes: int) -> None:
        if self._dataset is None:
            return
        while not self._queue.put(item, nbytes, timeout=0.5):
            self._check()
        self._check()

    def _check(self) -> None:
        if self.error is not None:
            err = self.error
            raise RecordingError(f"recording the episodes into `{self.root}` failed: {type(err).__name__}: {err}") from err

    # -- the writer thread ------------------------------------------------------------------

    def _run(self) -> None:
        assert self._dataset is not None
        open_: dict[int, _Open] = {}
        pending: list[Recorded] = []
        last = time.monotonic()
        serial = 0
        try:
            while True:
                try:
                    item, nbytes = self._queue.get(timeout=self._commit_every if pending else None)
                except Exception:  # queue.Empty: time to commit
                    item, nbytes = None, 0
                try:
                    if item is _STOP:
                        break
                    if item is not None:
                        kind, slot = item[0], item[1]
                        if kind == "row":
                            ep = open_.setdefault(slot, _Open())
                            serial = self._add(ep, item[2], slot, serial)
                        elif kind == "end" and slot in open_:
                            pending.append(self._ended(open_.pop(slot), item[2], item[3]))
                        elif kind == "drop" and slot in open_:
                            for video in open_.pop(slot).videos.values():
                                video.abandon()
                            self.stats["episodes_discarded"] += 1
                finally:
                    self._queue.done(nbytes)
                if pending and (item is None or time.monotonic() - last >= self._commit_every):
                    self._commit(pending)
                    pending, last = [], time.monotonic()
            self._commit(pending)
        except BaseException as e:  # said by the stepping side's next call
            self.error = e
            while True:  # let blocked `put`s through until the stop
                item, nbytes = self._queue.get()
                self._queue.done(nbytes)
                if item is _STOP:
                    break
        finally:
            for ep in open_.values():
                for video in ep.videos.values():
                    video.abandon()

    def _add(self, ep: _Open, row: dict[str, np.ndarray], slot: int, serial: int) -> int:
        assert self._dataset is not None
        for name, value in row.items():
            feature = self._dataset.features.get(name)
            if feature is not None and feature["dtype"] == "video":
                video = ep.videos.get(name)
                if video is None:
                    serial += 1
                    path = self._dataset.staged(f"eval-slot{slot}-{serial}.mp4")
                    video = ep.videos[name] = EpisodeVideo(path, self._video_fps, self._dataset.encodings[name])
                video.add(value)
            else:
                ep.rows.setdefault(name, []).append(value)
        ep.length += 1
        return serial

    def _ended(self, ep: _Open, task: str, success: bool | None) -> Recorded:
        assert self._dataset is not None
        columns: dict[str, np.ndarray] = {}
        for name, values in ep.rows.items():
            array = np.stack(values)
            if list(self._dataset.features[name]["shape"]) == [1]:
                array = array.reshape(-1)
            columns[name] = array
        terminated = columns["next.terminated"]
        done = np.zeros(ep.length, dtype=bool)
        done[-1] = True  # the protocol ended the episode here
        columns["next.done"] = done
        columns["next.truncated"] = done & ~terminated
        videos, stats = {}, {}
        for key, video in ep.videos.items():
            video.finish()
            videos[key], stats[key] = video.path, video.stats.result(video.frames)
        self.stats["frames"] += ep.length
        return Recorded(ep.length, columns, videos, stats, task, success)

    def _commit(self, episodes: list[Recorded]) -> None:
        if episodes:
            assert self._dataset is not None
            self._dataset.commit(episodes)
            self.stats["episodes_written"] += len(episodes)
