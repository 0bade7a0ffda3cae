"""One encoding per dataset: the stream parameters a camera's episodes are encoded with, read
from a dataset's `info.json` and its last video file, and checked to join its packets.

An append copies the new episodes' packets after the dataset's (no encoding again), and an MP4
keeps one stream configuration (H.264's SPS/PPS, AV1's sequence header): packets encoded with
other parameters decode wrong or not at all under it (x264 at `crf=40` after `crf=18` decodes
tens of levels off, openh264's after x264's fails). So an append encodes with the dataset's
parameters: the codec and pixel format `info.json` names, the size of its frames, and the
encoder, CRF and GOP its files say (envhub's MP4s carry them in a `comment` tag; x264 writes
its options into the stream; a file with neither, AV1 from LeRobot's writer, is taken as that
writer's defaults, with the GOP counted from its keyframes). Before anything is written, two
frames are encoded with those parameters and their stream configuration compared with the
file's: a dataset whose parameters cannot be reproduced is refused, naming what differs.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

#: Encoder settings besides CRF and GOP, per encoder. SVT-AV1 ignores `thread_count`: `lp=1`
#: (its "level of parallelism") is its own bound.
CODECS: dict[str, dict[str, str]] = {
    "libx264": {"preset": "veryfast", "tune": "zerolatency"},
    "libsvtav1": {"preset": "12", "svtav1-params": "lp=1"},
    "libaom-av1": {"cpu-used": "8", "row-mt": "1"},
    "libopenh264": {},
}
DEFAULT_CODEC = "libx264"
#: Codec names as `info.json` has them (LeRobot writes FFmpeg's canonical names).
CANONICAL = {"libx264": "h264", "libopenh264": "h264", "libsvtav1": "av1", "libaom-av1": "av1"}
#: The encoder for a codec `info.json` names, when nothing else says which.
ENCODER = {"h264": "libx264", "av1": "libsvtav1"}
#: The default CRF per encoder: x264's visually lossless 18; AV1 at LeRobot's writer's 30.
DEFAULT_CRF = {"libx264": 18, "libsvtav1": 30, "libaom-av1": 30}
DEFAULT_GOP = 2
#: What LeRobot's writer (`encode_video_frames`) uses when it is not told otherwise.
LEROBOT_AV1 = {"encoder": "libsvtav1", "crf": 30, "gop": 2}
TAG = "envhub-encoding"


@dataclass(frozen=True)
class Encoding:
    """How a camera's episodes are encoded."""

    encoder: str  # FFmpeg's encoder: libx264, libopenh264, libsvtav1, libaom-av1
    crf: int | None  # None: the encoder has no CRF (openh264)
    gop: int
    pix_fmt: str
    width: int
    height: int

    def options(self) -> dict[str, str]:
        options = dict(CODECS[self.encoder])
        if self.crf is not None:
            options["crf"] = str(self.crf)
        options["g"] = str(self.gop)
        return options

    def tag(self) -> str:
        """The MP4 `comment` tag that says these parameters."""
        return f"{TAG} encoder={self.encoder} crf={self.crf} g={self.gop}"

    def describe(self) -> str:
        crf = "" if self.crf is None else f" crf={self.crf}"
        return f"`{self.encoder}`{crf} g={self.gop} {self.pix_fmt} {self.width}x{self.height}"


def requested(codec: str | None, crf: int | None, gop: int | None, pix_fmt: str, width: int, height: int) -> Encoding:
    """A new camera's encoding: what was asked, the defaults for the rest."""
    encoder = codec or DEFAULT_CODEC
    if crf is None:
        crf = DEFAULT_CRF.get(encoder)
    elif encoder == "libopenh264":
        crf = None  # openh264 has no CRF; its bit rate is its own
    return Encoding(encoder, None if crf is None else int(crf), int(gop or DEFAULT_GOP), pix_fmt, width, height)


def _parse_tag(text: str) -> dict[str, str] | None:
    if not text.startswith(TAG + " "):
        return None
    return dict(part.split("=", 1) for part in text[len(TAG) + 1:].split() if "=" in part)


def _x264_options(packet: bytes) -> dict[str, str] | None:
    """The options x264 writes into its first packet (an SEI message), if it made the stream."""
    m = re.search(rb"x264 - core \d+.*?options: ([ -~]*)", packet, re.S)
    if m is None:
        return None
    return dict(p.split("=", 1) for p in m.group(1).decode().split() if "=" in p)


def _keyframe_gap(packets: list[Any]) -> int | None:
    """The largest gap between keyframes among the first packets (the GOP), if two are seen."""
    keys = [i for i, p in enumerate(packets) if p.is_keyframe]
    gaps = [b - a for a, b in zip(keys, keys[1:], strict=False)]
    return max(gaps) if gaps else None


def read(path: Path, feature: dict[str, Any]) -> Encoding:
    """The encoding of the dataset's video `path`, for the camera `feature` (its `info.json`
    entry). Raises `ValueError` naming what cannot be appended to."""
    import av

    info = feature.get("info", {})
    codec = info.get("video.codec")
    height, width = int(feature["shape"][0]), int(feature["shape"][1])
    with av.open(str(path)) as src:
        stream = src.streams.video[0]
        comment = src.metadata.get("comment", "")
        packets = []
        for packet in src.demux(stream):
            if packet.size:
                packets.append(packet)
            if len(packets) >= 64:
                break
        first = bytes(packets[0]) if packets else b""
        file_fmt = stream.codec_context.format.name if stream.codec_context.format else None
        size = (stream.codec_context.width, stream.codec_context.height)
    pix_fmt = info.get("video.pix_fmt") or file_fmt
    if file_fmt is not None and pix_fmt != file_fmt:
        raise ValueError(f"`info.json` says pixel format `{pix_fmt}`, its video `{path}` holds `{file_fmt}`")
    if size != (width, height):
        raise ValueError(f"`info.json` says {width}x{height} frames, its video `{path}` holds {size[0]}x{size[1]}")
    gop = _keyframe_gap(packets)
    tag = _parse_tag(comment)
    if tag is not None and tag.get("encoder") in CODECS:
        crf = None if tag.get("crf") in (None, "None") else int(tag["crf"])
        return Encoding(tag["encoder"], crf, int(tag.get("g", gop or DEFAULT_GOP)), pix_fmt, width, height)
    if codec == "h264":
        x264 = _x264_options(first)
        if x264 is not None and x264.get("rc") == "crf":
            crf = round(float(x264["crf"]))
            return Encoding("libx264", crf, int(x264.get("keyint", gop or DEFAULT_GOP)), pix_fmt, width, height)
        if x264 is not None:
            raise ValueError(f"its H.264 videos were encoded by x264 in rate control `{x264.get('rc')}`, not CRF")
        return Encoding("libopenh264", None, gop or DEFAULT_GOP, pix_fmt, width, height)
    if codec == "av1":  # no encoder options in the stream: LeRobot's writer's, the GOP as counted
        return Encoding(LEROBOT_AV1["encoder"], LEROBOT_AV1["crf"], gop or LEROBOT_AV1["gop"], pix_fmt, width, height)
    raise ValueError(f"its videos are `{codec}`; envhub appends to H.264 and AV1 videos only")


def conflicts(there: Encoding, codec: str | None, crf: int | None, gop: int | None) -> list[str]:
    """What was asked (`None`: not asked) that differs from the dataset's encoding."""
    out = []
    if codec is not None and codec != there.encoder:
        out.append(f"encoder `{codec}` asked, the dataset's is `{there.encoder}`")
    if crf is not None and there.crf is not None and int(crf) != there.crf and (codec or there.encoder) == there.encoder:
        out.append(f"crf={crf} asked, the dataset's is crf={there.crf}")
    if gop is not None and int(gop) != there.gop:
        out.append(f"gop={gop} asked, the dataset's is g={there.gop}")
    return out


def _configuration(data: bytes | str) -> tuple[str, bytes]:
    """The codec and stream configuration (`avcC`, `av1C`) of an MP4, as a reader sees it."""
    import av

    source = io.BytesIO(data) if isinstance(data, bytes) else data
    with av.open(source) as src:
        stream = src.streams.video[0]
        return stream.codec_context.name, bytes(stream.codec_context.extradata or b"")


def probe(encoding: Encoding, fps: int) -> bytes:
    """Two frames encoded with `encoding`, as an MP4 in memory."""
    import av
    import numpy as np

    buf = io.BytesIO()
    with av.open(buf, mode="w", format="mp4") as dst:
        stream = dst.add_stream(encoding.encoder, rate=fps, options=encoding.options())
        stream.width, stream.height, stream.pix_fmt = encoding.width, encoding.height, encoding.pix_fmt
        stream.codec_context.time_base = Fraction(1, fps)
        stream.codec_context.thread_count = 1
        for k in range(2):
            frame = np.full((encoding.height, encoding.width, 3), 60 * k + 40, np.uint8)
            vf = av.VideoFrame.from_ndarray(frame, format="rgb24")
            vf.pts = k
            dst.mux(stream.encode(vf))
        dst.mux(stream.encode(None))
    return buf.getvalue()


def check_joinable(path: Path, encoding: Encoding, fps: int) -> None:
    """Raises `ValueError` unless packets encoded with `encoding` join the video at `path`
    (the same stream configuration)."""
    theirs = _configuration(str(path))
    ours = _configuration(probe(encoding, fps))
    if theirs != ours:
        raise ValueError(
            f"its video `{path.name}` has another stream configuration than envhub's "
            f"{encoding.describe()} gives (its codec's parameter sets differ), so appended "
            "frames would not decode"
        )
