"""From Gymnasium spaces to LeRobot features: which column or video each part of a frame goes to.

A Box of uint8 `(height, width, 3)` is a camera image and becomes a video; every other leaf is a
numeric column, flattened to one dimension (LeRobot's loader reads 1-D columns as fixed-length
sequences, and a shape of `(1,)` as a scalar). Values keep their dtype, so states and actions
load back bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from .errors import UnrecordableSpaceError

#: The video of `render()` frames.
RENDER_KEY = "observation.images.render"


@dataclass(frozen=True)
class Column:
    """One LeRobot feature: `path` leads to its value in a (Dict) observation."""

    name: str
    path: tuple[str, ...]
    dtype: np.dtype
    shape: tuple[int, ...]  # per frame, as stored: `(n,)` for numbers, `(h, w, 3)` for a video
    video: bool

    def batch(self, value: Any, num_envs: int) -> np.ndarray:
        """This column's values for every env of a batched observation, as stored."""
        for key in self.path:
            value = value[key]
        array = np.asarray(value)
        if self.video:
            return array
        return array.reshape(num_envs, -1)

    def feature(self, fps: int, codec: str = "", pix_fmt: str = "") -> dict[str, Any]:
        """The entry of `meta/info.json`'s `features`."""
        if not self.video:
            return {"dtype": self.dtype.name, "shape": list(self.shape), "names": None}
        h, w, c = self.shape
        return {
            "dtype": "video",
            "shape": [h, w, c],
            "names": ["height", "width", "channels"],
            "info": {
                "video.height": h,
                "video.width": w,
                "video.codec": codec,
                "video.pix_fmt": pix_fmt,
                "video.is_depth_map": False,
                "video.fps": fps,
                "video.channels": c,
                "has_audio": False,
            },
        }


def is_image(space: spaces.Space) -> bool:
    """A camera image: uint8 `(height, width, 3)`."""
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and space.shape[2] == 3
    )


def _numeric(name: str, path: tuple[str, ...], space: spaces.Space, what: str) -> Column:
    if isinstance(space, spaces.Discrete):
        return Column(name, path, np.dtype(np.int64), (1,), False)
    if isinstance(space, spaces.Box | spaces.MultiDiscrete | spaces.MultiBinary):
        n = int(np.prod(space.shape, dtype=np.int64))
        return Column(name, path, np.dtype(space.dtype), (n,), False)
    raise UnrecordableSpaceError(
        f"the {what} space `{space}` cannot be recorded into a LeRobot dataset\n"
        "hint: recording takes Box, Discrete, MultiDiscrete and MultiBinary spaces, and Dict "
        "spaces of those (no Tuple, Text or Graph)"
    )


def observation_columns(space: spaces.Space) -> list[Column]:
    """Columns of an observation: `observation.state` for a plain one; for a Dict,
    `observation.images.<key>` per image and `observation.<key>` per other entry (nested keys
    joined with `.`; an entry named `state` is `observation.state`)."""
    if not isinstance(space, spaces.Dict):
        if is_image(space):
            return [Column("observation.image", (), np.dtype(np.uint8), tuple(space.shape), True)]
        return [_numeric("observation.state", (), space, "observation")]
    columns: list[Column] = []

    def walk(sub: spaces.Dict, path: tuple[str, ...]) -> None:
        for key, leaf in sub.spaces.items():
            where = (*path, str(key))
            dotted = ".".join(where)
            if "/" in dotted:
                raise UnrecordableSpaceError(
                    f"the observation key `{dotted}` holds `/`, which LeRobot feature names cannot\n"
                    "hint: rename the key (a wrapper such as gymnasium.wrappers.TransformObservation)"
                )
            if isinstance(leaf, spaces.Dict):
                walk(leaf, where)
            elif is_image(leaf):
                columns.append(Column(f"observation.images.{dotted}", where, np.dtype(np.uint8), leaf.shape, True))
            else:
                name = "observation.state" if dotted == "state" else f"observation.{dotted}"
                columns.append(_numeric(name, where, leaf, f"observation `{dotted}`"))

    walk(space, ())
    return columns


def action_column(space: spaces.Space) -> Column:
    return _numeric("action", (), space, "action")


#: Per-step columns besides the observation and the action (LeRobot's `next.*` convention:
#: what the step that took this frame's action returned).
STEP_COLUMNS = [
    Column("next.reward", (), np.dtype(np.float64), (1,), False),
    Column("next.done", (), np.dtype(np.bool_), (1,), False),
    Column("next.terminated", (), np.dtype(np.bool_), (1,), False),
    Column("next.truncated", (), np.dtype(np.bool_), (1,), False),
]

#: The index columns every LeRobot dataset has, in its order.
INDEX_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}


def features(columns: list[Column], fps: int, codec: str, extra_videos: dict[str, tuple[int, ...]] | None = None) -> dict[str, dict]:
    """`info.json`'s `features` for a recording of `columns` (observation, action and step
    columns; `codec` as `info.json` names it, `h264`) plus `extra_videos` (key: frame shape),
    the index columns last."""
    out: dict[str, dict] = {}
    videos: dict[str, tuple[int, ...]] = {}
    for c in columns:
        if c.video:
            videos[c.name] = c.shape
        else:
            out[c.name] = c.feature(fps)
    videos.update(extra_videos or {})
    for key, (h, w, ch) in videos.items():
        out[key] = Column(key, (), np.dtype(np.uint8), (h, w, ch), True).feature(fps, codec, _pix_fmt(w, h))
    return out | INDEX_FEATURES


def frame_rate(declared: Any, fps: int | None) -> int:
    """The dataset's fps: `fps` if given, else the env's `render_fps` (`declared`), which must
    be a positive whole number (LeRobot's)."""
    value = fps if fps is not None else declared
    if value is None:
        raise ValueError(
            "the env declares no frame rate (`metadata[\"render_fps\"]`), which the dataset's "
            "timestamps need\nhint: pass `fps=` (steps per second of env time)"
        )
    if float(value) <= 0 or not float(value).is_integer():
        raise ValueError(
            f"the dataset's fps must be a positive whole number (LeRobot's), got `{value}`\n"
            "hint: pass `fps=` with the nearest whole number"
        )
    return int(value)


def _pix_fmt(width: int, height: int) -> str:
    from ._video import pix_fmt

    return pix_fmt(width, height)
