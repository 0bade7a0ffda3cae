"""MP4 videos through PyAV (FFmpeg's encoders): one file per episode and camera, encoded frame
by frame as the episode runs, so no episode's raw frames are ever held in memory.

The default encoder is x264 (`libx264`): an open x264 encoder costs a few MB and runs on its
caller's thread, so a recorder can keep one per env and camera. SVT-AV1 (`libsvtav1`, LeRobot's
own default) writes smaller files but runs a pipeline of threads of its own in every open
encoder (16 at its least parallel, `lp=1`; no setting makes fewer) and costs about 80 MB: one
per env and camera would take threads and memory by the envs. Its episodes are encoded
losslessly first (FFV1, on the caller's thread, in the staging folder) and into AV1 when the
episode ends (`finish`), so that a recorder has at most one SVT-AV1 encoder open per encoding
thread. Keyframes every `gop` frames (2, as LeRobot does) let a data loader decode any frame
quickly.
"""

from __future__ import annotations

import os
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ._encoding import CODECS, DEFAULT_CODEC, Encoding
from ._stats import level_quantiles


def check_codec(codec: str) -> None:
    """Raises a `ValueError` naming the codecs this PyAV build can encode with."""
    import av

    usable = [c for c in CODECS if c in av.codecs_available]
    if codec not in CODECS or codec not in av.codecs_available:
        raise ValueError(
            f"unknown or unavailable video codec `{codec}`; this PyAV build encodes with "
            + ", ".join(f"`{c}`" for c in usable)
            + f"\nhint: codec=`{DEFAULT_CODEC}` (the default) works with many envs at once"
        )


def pix_fmt(width: int, height: int) -> str:
    """`yuv420p` (what every player reads) when both sides are even, which 4:2:0 needs;
    `yuv444p` otherwise."""
    return "yuv420p" if width % 2 == 0 and height % 2 == 0 else "yuv444p"


#: Encoders that run threads of their own whatever FFmpeg's thread count: an episode is encoded
#: with them when it ends, from its lossless copy (`LOSSLESS`).
DEFERRED = frozenset({"libsvtav1"})
#: The lossless copy of a deferred episode: FFV1 (FFmpeg's own, intra-only: no thread, and
#: decoded back to the very RGB frames), in Matroska.
LOSSLESS = ("ffv1", "bgr0", "matroska")


def _open(
    path: Path, fps: int, encoding: Encoding, fmt: str, codec: str, pix_fmt: str, options: Any = None, comment: Any = None
) -> tuple[Any, Any]:
    """A container of format `fmt` at `path` and its one video stream (`codec`, `pix_fmt`, the
    encoding's size), opened to encode one frame per `1 / fps`."""
    import av

    container = av.open(str(path), mode="w", format=fmt)
    try:
        if comment is not None:
            container.metadata["comment"] = comment  # read back by appends
        stream = container.add_stream(codec, rate=fps, **({} if options is None else {"options": options}))
        stream.width, stream.height, stream.pix_fmt = encoding.width, encoding.height, pix_fmt
        stream.codec_context.time_base = Fraction(1, fps)
        # One thread per encoder (FFmpeg's default is one per core each): the recorder bounds
        # the threads that encode by calling encoders from `encode_threads` threads.
        stream.codec_context.thread_count = 1
    except BaseException:
        container.close()
        raise
    return container, stream


def _output(path: Path, fps: int, encoding: Encoding) -> tuple[Any, Any]:
    """An MP4 at `path` and its video stream, opened to encode with `encoding`."""
    return _open(path, fps, encoding, "mp4", encoding.encoder, encoding.pix_fmt, encoding.options(), encoding.tag())


def _lossless(path: Path, fps: int, encoding: Encoding) -> tuple[Any, Any]:
    """The lossless copy of a deferred episode (`LOSSLESS`), at the encoding's size."""
    codec, pix_fmt, fmt = LOSSLESS
    return _open(path, fps, encoding, fmt, codec, pix_fmt)


class EpisodeVideo:
    """One episode of one camera, encoded into `path` frame by frame (frame `k` at time
    `k / fps`); with a `DEFERRED` encoder, into a lossless copy beside it, encoded into `path`
    by `finish`."""

    def __init__(self, path: Path, fps: int, encoding: Encoding) -> None:
        self.path = path
        self.fps, self.encoding = fps, encoding
        self.shape = (encoding.height, encoding.width, 3)
        self.frames = 0
        self.finished = False
        self._copy = path.with_name(path.name + ".lossless.mkv") if encoding.encoder in DEFERRED else None
        if self._copy is None:
            self._container, self._stream = _output(path, fps, encoding)
        else:
            self._container, self._stream = _lossless(self._copy, fps, encoding)
        self.stats = _ChannelStats()

    def add(self, frame: np.ndarray) -> None:
        import av

        if frame is None or frame.shape != self.shape or frame.dtype != np.uint8:
            got = "no frame" if frame is None else f"{frame.dtype} {frame.shape}"
            raise ValueError(
                f"a frame of {got} in a video of uint8 {self.shape}\nhint: an env's frames must keep "
                "their size through a recording"
            )
        self.stats.add(frame)
        vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")
        vf.pts = self.frames
        vf.time_base = self._stream.codec_context.time_base
        self._container.mux(self._stream.encode(vf))
        self.frames += 1

    def finish(self) -> None:
        """Flushes the encoder and closes the file; with a `DEFERRED` encoder, first encodes
        the episode from its lossless copy (one such encoder open, on this thread). Once."""
        if self.finished:
            return
        self._container.mux(self._stream.encode(None))
        self._container.close()
        if self._copy is not None:
            self._encode_copy(self._copy)
            self._copy.unlink()
        self.finished = True

    def _encode_copy(self, copy: Path) -> None:
        import av

        container, stream = _output(self.path, self.fps, self.encoding)
        with container, av.open(str(copy)) as src:
            source = src.streams.video[0]
            source.codec_context.thread_count = 1
            k = 0
            for decoded in src.decode(source):
                vf = av.VideoFrame.from_ndarray(decoded.to_ndarray(format="rgb24"), format="rgb24")
                vf.pts = k
                vf.time_base = stream.codec_context.time_base
                container.mux(stream.encode(vf))
                k += 1
            container.mux(stream.encode(None))
        if k != self.frames:
            raise ValueError(f"`{copy}` gave {k} frames back, {self.frames} were encoded into it")

    def abandon(self) -> None:
        """Closes and removes the file (an episode that is not kept)."""
        try:
            self._container.close()
        except Exception:  # a half-written file is removed either way
            pass
        for path in (self.path, self._copy):
            if path is not None:
                try:
                    os.unlink(path)
                except FileNotFoundError:
                    pass


def count_frames(path: Path) -> int:
    """The video packets (frames) of an MP4, read without decoding."""
    import av

    with av.open(str(path)) as src:
        return sum(1 for p in src.demux(src.streams.video[0]) if p.size)


def concatenate(parts: list[tuple[Path, int]], out: Path, fps: int, tag: str | None = None) -> None:
    """Writes the first `frames` frames of each `(mp4, frames)` of `parts`, one after another,
    into the MP4 `out`: packets are copied (no encoding again) with their times moved on by
    the frames before them, so part `k` starts at the sum of the earlier parts' frames over
    `fps`. Parts come from `EpisodeVideo`s (or earlier concatenations) of one camera: the same
    encoder and settings (`tag`: the `comment` tag that says them), no reordered frames, a
    keyframe first."""
    import av

    with av.open(str(out), mode="w", format="mp4") as dst:
        if tag is not None:
            dst.metadata["comment"] = tag
        stream = None
        offset = 0  # frames before this part
        for path, frames in parts:
            with av.open(str(path)) as src:
                s = src.streams.video[0]
                if stream is None:
                    stream = dst.add_stream_from_template(s, opaque=True)  # no encoder: AV1 decodes with dav1d
                tb = s.time_base
                shift = int(round(Fraction(offset, fps) / tb))
                # A packet's frame, round(pts * tb * fps), is under `frames` when pts * tb * fps
                # < frames - 1/2 (at exactly a half, round() goes to the even neighbour): in
                # integers, as Fractions per packet cost most of a join of short episodes.
                scaled, bound = 2 * tb.numerator * fps, (2 * frames - 1) * tb.denominator
                half_kept = frames % 2 == 1
                taken = 0
                for packet in src.demux(s):
                    if not packet.size or packet.pts is None:
                        continue
                    x = packet.pts * scaled
                    if x > bound or (x == bound and not half_kept):
                        continue
                    packet.pts += shift
                    packet.dts = packet.pts if packet.dts is None else packet.dts + shift
                    packet.stream = stream
                    dst.mux(packet)
                    taken += 1
                if taken != frames:
                    raise ValueError(f"`{path}` holds {taken} frames, {frames} expected")
            offset += frames


class _ChannelStats:
    """Per-channel min, max, mean, std and quantiles of an episode's frames in [0, 1], as
    LeRobot keeps for cameras (shape `(3, 1, 1)`), over frames subsampled to about 150 pixels
    a side (LeRobot samples frames and shrinks them likewise)."""

    def __init__(self) -> None:
        self.counts = np.zeros((3, 256), dtype=np.int64)  # pixels by channel and level

    def add(self, frame: np.ndarray) -> None:
        step = max(1, max(frame.shape[:2]) // 150)
        px = frame[::step, ::step].reshape(-1, 3)
        for c in range(3):
            self.counts[c] += np.bincount(px[:, c], minlength=256)

    def result(self, frames: int) -> dict[str, Any]:
        levels = np.arange(256) / 255.0
        n = np.maximum(self.counts.sum(1), 1)
        mean = (self.counts * levels).sum(1) / n
        std = np.sqrt(np.maximum((self.counts * levels**2).sum(1) / n - mean**2, 0.0))
        seen = self.counts > 0
        lo = np.array([levels[np.flatnonzero(s)[0]] if s.any() else 0.0 for s in seen])
        hi = np.array([levels[np.flatnonzero(s)[-1]] if s.any() else 0.0 for s in seen])
        shape = (3, 1, 1)
        return {
            "min": lo.reshape(shape),
            "max": hi.reshape(shape),
            "mean": mean.reshape(shape),
            "std": std.reshape(shape),
            "count": np.array([frames]),
            **level_quantiles(self.counts),
        }
