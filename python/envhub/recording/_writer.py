"""The writer thread: turns the steps the recorder hands it into episodes on disk.

It keeps the rows of the episodes in flight (`_rows.py`: one copy per step and column, whatever
the number of envs), encodes each env's camera frames into that episode's MP4 as they arrive,
and when an env's episode ends takes its rows out. Ended episodes are committed together, at
most every `commit_every` seconds (or four times as long as the last commit took, if longer),
as soon as their rows and statistics reach `PENDING_BYTES` (or `queue_bytes`, if smaller), and
when the recorder closes. After each commit the allocators are asked to give back what it freed
(`_memory.py`).
"""

from __future__ import annotations

import queue
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._budget import ByteQueue
from ._dataset import Dataset, Episode
from ._memory import release
from ._rows import Rows
from ._spill import width_of
from ._video import EpisodeVideo


@dataclass
class Step:
    """One lock-step `step` of every env: the observation before it (`obs` by column), the
    camera frames of that observation (`frames`: `render()`'s, or `None`), the actions, what
    the step returned, and which envs really stepped (`valid`: not an autoreset step)."""

    obs: dict[str, np.ndarray]
    frames: list[np.ndarray] | None
    action: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    valid: np.ndarray
    success: list[bool | None] | None
    task: str
    failed: np.ndarray | None = None  # envs that failed in this step: their episodes are dropped
    gap: bool = False  # steps before this one were dropped (queue full)


@dataclass
class Reset:
    """A reset of the envs in `mask` (all when `None`): their episodes in flight end unfinished."""

    mask: np.ndarray | None
    gap: bool = False


STOP = object()
#: Ended episodes' rows (and their statistics' rows) held before a commit comes early: a commit
#: takes a few times this for a moment (its copies, Parquet's buffers), so it bounds that too.
PENDING_BYTES = 16 * 2**20


class Writer:
    """The thread that owns the dataset once recording starts."""

    def __init__(
        self,
        dataset: Dataset,
        num_envs: int,
        numeric: list[str],
        videos: list[str],
        render_key: str | None,
        fps: int,
        keep: str,
        commit_every: float,
        queue_bytes: int,
        stats: dict[str, Any],
        max_episodes: int | None = None,
        encode_threads: int = 1,
    ) -> None:
        self.dataset = dataset
        self.n = num_envs
        self.numeric = numeric
        self.videos = videos  # observation images, by column
        self.render_key = render_key
        self.video_keys = [*videos, *([render_key] if render_key else [])]
        self.fps = fps
        self.keep = keep
        self.max_episodes = max_episodes
        self.commit_every = commit_every
        self.stats = stats
        self.queue = ByteQueue(queue_bytes)
        self._pending_limit = min(queue_bytes, PENDING_BYTES)
        self.error: BaseException | None = None
        self._serial = 0
        self._rows = Rows(num_envs, lambda i: self._staged(f"env{i}-rows.bin"))
        self._t = 0  # global index of the next row
        self._start = np.zeros(num_envs, dtype=np.int64)
        self._live = np.zeros(num_envs, dtype=bool)  # recording the env's current episode
        self._task = [""] * num_envs
        self._encoders: list[dict[str, EpisodeVideo]] = [{} for _ in range(num_envs)]
        # PyAV releases the GIL while FFmpeg encodes, so envs' frames are encoded in parallel:
        # env `i`'s on thread `i % threads`, each step's frames before the next step's.
        threads = min(encode_threads, num_envs) if self.video_keys else 1
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="envhub-encoder") if threads > 1 else None
        self._threads = threads
        self._pending: list[Episode] = []
        self._pending_bytes = 0  # their rows: a commit comes early past `PENDING_BYTES`
        self._last_commit = time.monotonic()
        self._interval = commit_every  # until a commit: `commit_every`, or 4x the last commit's time
        self.thread = threading.Thread(target=self._run, name="envhub-recorder", daemon=True)
        self.thread.start()

    # The thread ----------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while True:
                wait = max(0.0, self._interval - (time.monotonic() - self._last_commit))
                try:
                    item, nbytes = self.queue.get(timeout=wait if self._pending else None)
                except queue.Empty:
                    self._commit()
                    continue
                if item is STOP:
                    break
                try:
                    if item.gap:
                        self._gap()
                    if isinstance(item, Reset):
                        self._reset(item.mask)
                    else:
                        self._step(item)
                finally:
                    del item  # its arrays, before the budget says they are gone
                    self.queue.done(nbytes)
                if self._pending and (time.monotonic() - self._last_commit >= self._interval
                                      or self._pending_bytes >= self._pending_limit):
                    self._commit()
            self._commit()
        except BaseException as e:  # reported by the recorder on its next call
            self.error = e
            while True:  # let the recorder's blocked `put`s through until it sees the error
                try:
                    item, nbytes = self.queue.get(timeout=1.0)
                except queue.Empty:
                    continue
                self.queue.done(nbytes)
                if item is STOP:
                    break
        finally:
            for i in range(self.n):
                self._abandon(i)
            if self._pool is not None:
                self._pool.shutdown()

    def _gap(self) -> None:
        """Steps were dropped: every episode in flight misses frames and is dropped; each env
        records again from its next episode."""
        for i in np.flatnonzero(self._live):
            self._abandon(i)
            self.stats["episodes_dropped"] += 1
        self._live[:] = False

    def _reset(self, mask: np.ndarray | None) -> None:
        envs = range(self.n) if mask is None else np.flatnonzero(mask)
        for i in envs:
            if self._live[i] and self._start[i] < self._t:
                self.stats["episodes_cut"] += 1
            self._abandon(i)
            self._live[i] = True
            self._start[i] = self._t

    def _step(self, s: Step) -> None:
        t = self._t
        values = {name: s.obs[name] for name in self.numeric if name in s.obs}
        values["action"] = s.action
        values["next.reward"] = s.reward
        values["next.terminated"] = s.terminated
        values["next.truncated"] = s.truncated
        values["next.done"] = np.logical_or(s.terminated, s.truncated)
        self._rows.append(values, self._start, self._live)
        self._t += 1
        done = values["next.done"]
        # Masks over the envs, so that only envs with something to do cost a Python step.
        recording = s.valid & self._live
        for i in np.flatnonzero(recording & (self._start == t)):
            self._task[i] = s.task
        if self.video_keys and not self._full():
            self._encode(np.flatnonzero(recording), s)
        ended = np.flatnonzero(recording & done)
        if self.video_keys and len(ended):
            self._finish([i for i in ended if self._keeps(s.success[i] if s.success is not None else None)])
        for i in ended:
            self._end(i, t, s.success[i] if s.success is not None else None)
        # After an autoreset step, or the end of an episode (recorded or not, after a drop),
        # the env's next episode starts with the next row.
        if s.failed is not None:  # their episodes are dropped; recorded again from their reset
            for i in np.flatnonzero(s.failed & self._live):
                self._abandon(i)
                self.stats["episodes_dropped"] += 1
        restart = ~s.valid | done
        self._live[restart] = True
        self._start[restart] = t + 1
        if s.failed is not None:
            self._live[s.failed] = False

    def _encode(self, envs: np.ndarray, s: Step) -> None:
        jobs: list[list[tuple[EpisodeVideo, np.ndarray]]] = [[] for _ in range(self._threads)]
        for i in envs:
            encoders = self._encoders[i]
            if not encoders:  # the episode's first frame: its files
                for key in self.video_keys:
                    path = self._staged(f"env{i}.mp4")
                    encoders[key] = EpisodeVideo(path, self.fps, self.dataset.encodings[key])
            job = jobs[i % self._threads]
            for key in self.videos:
                job.append((encoders[key], s.obs[key][i]))
            if self.render_key is not None:
                job.append((encoders[self.render_key], s.frames[i]))  # type: ignore[index]
        if self._pool is None:
            _encode_frames(jobs[0])
        else:
            list(self._pool.map(_encode_frames, jobs))  # re-raises an encoder's error

    def _finish(self, envs: list[int]) -> None:
        """Finishes the videos of the episodes of `envs`, which end and are kept, on the
        encoding threads (env `i`'s on thread `i % threads`, one after another): with SVT-AV1,
        which encodes an episode as it ends (`_video.py`), each thread has one encoder open at
        a time."""
        jobs: list[list[EpisodeVideo]] = [[] for _ in range(self._threads)]
        for i in envs:
            jobs[i % self._threads].extend(self._encoders[i].values())
        if self._pool is None:
            _finish_videos(jobs[0])
        else:
            list(self._pool.map(_finish_videos, jobs))  # re-raises an encoder's error

    def _keeps(self, success: bool | None) -> bool:
        """Whether an episode that ends now, with `success`, is kept."""
        return not (self.keep == "success" and not success) and not self._full()

    def _staged(self, name: str) -> Path:
        """A new file's path in the dataset's staging folder."""
        self._serial += 1
        return self.dataset.staged(f"{self._serial}-{name}")

    def _abandon(self, i: int) -> None:
        self._rows.forget(i)
        for video in self._encoders[i].values():
            video.abandon()
        self._encoders[i] = {}

    def _end(self, i: int, t: int, success: bool | None) -> None:
        start = int(self._start[i])
        if self.keep == "success" and not success:
            self._abandon(i)
            self.stats["episodes_filtered"] += 1
            return
        if self._full():
            self._abandon(i)
            self.stats["episodes_beyond"] += 1
            return
        names = [*self.numeric, "action", "next.reward", "next.terminated", "next.truncated", "next.done"]
        columns = self._rows.episode(names, i, start, t)
        for name, values in columns.items():
            if isinstance(values, np.ndarray) and list(self.dataset.features[name]["shape"]) == [1]:
                columns[name] = values.reshape(-1)
        # Its rows held in memory, and its row of `meta/episodes/` (ten statistics per value).
        self._pending_bytes += sum((c.nbytes if isinstance(c, np.ndarray) else 0) + 80 * width_of(c)
                                   for c in columns.values())
        videos, video_stats = {}, {}
        for key, video in self._encoders[i].items():
            video.finish()
            videos[key] = video.path
            video_stats[key] = video.stats.result(video.frames)
        self._encoders[i] = {}
        length = t - start + 1
        self._pending.append(Episode(length, columns, videos, video_stats, self._task[i], success))
        self.stats["frames_kept"] += length
        self.stats["episodes_kept"] += 1
        if self._full():  # no episode in flight can be kept: nothing more to encode
            for j in range(self.n):
                self._abandon(j)

    def _full(self) -> bool:
        return self.max_episodes is not None and self.stats["episodes_kept"] >= self.max_episodes

    def _commit(self) -> None:
        start = time.monotonic()
        if self._pending:
            pending, self._pending, self._pending_bytes = self._pending, [], 0
            self.dataset.commit(pending)
            self.stats["episodes_written"] += len(pending)
            del pending
            release()
        self._last_commit = time.monotonic()
        # Spacing commits by four times their duration keeps committing (and the joins of small
        # files it may do) under a fifth of the writer's time.
        self._interval = max(self.commit_every, 4 * (self._last_commit - start))


def _encode_frames(job: list[tuple[EpisodeVideo, np.ndarray]]) -> None:
    for video, frame in job:
        video.add(frame)


def _finish_videos(job: list[EpisodeVideo]) -> None:
    for video in job:
        video.finish()
