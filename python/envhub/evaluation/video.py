"""One MP4 per evaluated episode (or per failed one), encoded off the stepping path.

The runner hands each env's frame to `EpisodeVideos.frame` as it steps: the frame is copied
(an observation may live in shared memory the next step overwrites) and queued; a writer
thread encodes it. The queue is bounded (`queue_frames`), so a writer that falls behind
slows the evaluation instead of filling memory. Videos are H.264 (`libx264`, else
`libopenh264`) in yuv420p with the index at the front of the file (`faststart`): what
browsers play in the HTML report, from the first byte. 4:2:0 needs even sides, so an odd
frame is padded by one black row or column.

An episode's video is written to a hidden file while it runs and renamed once it is kept
(`finish`), so a folder never holds half a video under a final name; a discarded or
successful-when-only-failures episode leaves nothing.
"""

from __future__ import annotations

import os
import queue
import re
import threading
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ..wire.errors import EnvHubError
from .policy import Episode

DEFAULT_FPS = 20
# Frames waiting for the writer (a 256x256 frame is 192 KiB: 512 of them are under 100 MiB).
DEFAULT_QUEUE_FRAMES = 512
_CODECS = ("libx264", "libopenh264")
_STOP = object()


class VideoError(EnvHubError, RuntimeError):
    """The writer could not encode or write a video (disk full, no H.264 encoder, a frame
    that is not an image); raised by the next call after it happened."""


class EpisodeVideos:
    """Episode videos in `folder`/`subfolder` (the evaluation's output folder and
    `videos/`), one encoder per env slot.

    `frame(slot, frame)` adds a `HxWx3` uint8 frame to the slot's current episode;
    `finish(slot, episode, success)` ends it and returns its path relative to `folder`
    (`videos/libero-spatial_0_ep0003.mp4`: what the results file records and the report
    plays), or None when no video is kept (no frames, or a success under `only_failures`);
    `discard(slot)` drops the slot's current episode; `close()` waits for every video to be
    written. The file behind a returned path is complete once `close()` returns."""

    def __init__(
        self,
        folder: str | os.PathLike[str],
        only_failures: bool = False,
        fps: float = DEFAULT_FPS,
        *,
        subfolder: str = "videos",
        crf: int = 23,
        queue_frames: int = DEFAULT_QUEUE_FRAMES,
    ) -> None:
        if not (isinstance(fps, (int, float)) and 0 < fps <= 1000):
            raise ValueError(f"fps must be a number of frames per second in (0, 1000], got {fps!r}")
        if queue_frames < 1:
            raise ValueError(f"queue_frames must be at least 1, got {queue_frames}")
        self.root = Path(folder)
        self.folder = self.root / subfolder
        self.folder.mkdir(parents=True, exist_ok=True)
        self.only_failures = only_failures
        # 29.97 is 30000/1001: MP4 keeps a rational rate.
        self.fps = Fraction(fps).limit_denominator(1001)
        self.crf = crf
        self.codec = _codec()
        self._queue: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._frames: dict[int, int] = {}  # frames given per slot this episode (caller's side)
        self._shapes: dict[int, tuple[int, ...]] = {}
        self._error: BaseException | None = None
        self._closed = False
        self._thread = threading.Thread(target=self._write, name="envhub-videos", daemon=True)
        self._thread.start()

    # -- the caller's side ----------------------------------------------------------------

    def frame(self, slot: int, frame: np.ndarray) -> None:
        """Queues a copy of `frame` (HxWx3 uint8) for `slot`'s current episode."""
        self._check()
        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(
                f"a video frame is an HxWx3 uint8 image; slot {slot} gave {frame.dtype} {frame.shape}"
            )
        shape = self._shapes.setdefault(slot, frame.shape)
        if frame.shape != shape:
            raise ValueError(
                f"slot {slot}'s frames changed size within an episode, from {shape[:2]} to {frame.shape[:2]}"
            )
        self._frames[slot] = self._frames.get(slot, 0) + 1
        self._put(("frame", slot, np.array(frame, copy=True)))

    def discard(self, slot: int) -> None:
        """Drops `slot`'s current episode: its video is not kept."""
        self._check()
        self._frames.pop(slot, None)
        self._shapes.pop(slot, None)
        self._put(("end", slot, None))

    def finish(self, slot: int, episode: Episode, success: bool) -> str | None:
        """Ends `slot`'s current episode: returns its video's path (relative, `/`-separated)
        or None when none is kept."""
        self._check()
        frames = self._frames.pop(slot, 0)
        self._shapes.pop(slot, None)
        if frames == 0 or (self.only_failures and success):
            self._put(("end", slot, None))
            return None
        path = self.folder / video_name(episode)
        self._put(("end", slot, path))
        return path.relative_to(self.root).as_posix()

    def close(self) -> None:
        """Writes what is queued, drops episodes never finished, and stops the writer."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join()
        if self._error is not None:
            raise VideoError(
                f"writing episode videos under {self.folder} failed: {self._error}"
            ) from self._error

    def __enter__(self) -> EpisodeVideos:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check(self) -> None:
        if self._error is not None:
            raise VideoError(
                f"writing episode videos under {self.folder} failed: {self._error}"
            ) from self._error
        if self._closed:
            raise VideoError("the episode videos are closed")

    def _put(self, item: Any) -> None:
        # Blocks while the writer is `queue_frames` behind; wakes to notice a dead writer.
        while True:
            try:
                self._queue.put(item, timeout=1.0)
                return
            except queue.Full:
                if not self._thread.is_alive():
                    self._check()
                    raise VideoError("the video writer stopped") from None

    # -- the writer thread ------------------------------------------------------------------

    def _write(self) -> None:
        open_: dict[int, _Video] = {}
        try:
            while True:
                item = self._queue.get()
                if item is _STOP:
                    break
                kind, slot, value = item
                if self._error is not None:
                    continue  # drain, so the caller never blocks on a dead writer
                try:
                    if kind == "frame":
                        video = open_.get(slot)
                        if video is None:
                            video = open_[slot] = _Video(
                                self.folder, slot, value.shape, self.fps, self.codec, self.crf
                            )
                        video.add(value)
                    else:
                        video = open_.pop(slot, None)
                        if video is not None:
                            video.end(value)
                except BaseException as exc:
                    self._error = exc
        finally:
            for video in open_.values():
                video.end(None)


class _Video:
    """One episode's encoder, writing a hidden file beside where the video will go."""

    def __init__(
        self, folder: Path, slot: int, shape: tuple[int, ...], fps: Fraction, codec: str, crf: int
    ) -> None:
        import av

        self.height, self.width = shape[0], shape[1]
        self.padded = (self.height + self.height % 2, self.width + self.width % 2)
        self.partial = folder / f".slot{slot}.partial.mp4"
        self.count = 0
        self.container = av.open(
            str(self.partial), mode="w", format="mp4", options={"movflags": "+faststart"}
        )
        try:
            options = (
                {"preset": "veryfast", "tune": "zerolatency", "crf": str(crf)} if codec == "libx264" else {}
            )
            stream = self.container.add_stream(codec, rate=fps, options=options)
            stream.height, stream.width = self.padded
            stream.pix_fmt = "yuv420p"
            stream.codec_context.time_base = 1 / fps
            self.stream = stream
        except BaseException:
            self.container.close()
            raise

    def add(self, frame: np.ndarray) -> None:
        import av

        if frame.shape[:2] != self.padded:
            padded = np.zeros((*self.padded, 3), dtype=np.uint8)
            padded[: self.height, : self.width] = frame
            frame = padded
        vf = av.VideoFrame.from_ndarray(frame, format="rgb24")
        vf.pts = self.count
        vf.time_base = self.stream.codec_context.time_base
        self.container.mux(self.stream.encode(vf))
        self.count += 1

    def end(self, path: Path | None) -> None:
        """Closes the file and renames it to `path`, or removes it (None)."""
        try:
            if path is not None:
                self.container.mux(self.stream.encode(None))
            self.container.close()
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                os.replace(self.partial, path)
        finally:
            if self.partial.exists():
                self.partial.unlink()


def video_name(episode: Episode) -> str:
    """The file name of an episode's video: `<task id>_ep<index>.mp4`, with characters
    other than letters, digits, `.`, `-` and `_` made `_` (`libero-spatial/3#7` is
    `libero-spatial_3_ep0007.mp4`)."""
    return f"{re.sub(r'[^A-Za-z0-9._-]', '_', episode.task.id)}_ep{episode.index:04d}.mp4"


def _codec() -> str:
    import av

    for codec in _CODECS:
        if codec in av.codecs_available:
            return codec
    raise VideoError(
        f"this PyAV build has no H.264 encoder ({' or '.join(_CODECS)}); episode videos need one"
    )
