"""LeRobot dataset v3 files, written with pyarrow and PyAV (no torch in envhub's install).

Each episode gets its own data file, episode-metadata file and video files
(`chunk-{ep // 1000}/file-{ep % 1000}`), each written to a temporary name and renamed;
`meta/tasks.parquet` and `meta/info.json` follow, `info.json` last. A crash therefore loses at
most the episode in flight; files of episodes `info.json` does not count are removed when the
dataset is opened again.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

CODEBASE_VERSION = "v3.0"
CHUNK = 1000
DEFAULT_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}


class LayoutError(ValueError):
    """An existing dataset whose layout differs from the one being recorded."""


def _rel(kind: str, ep: int, key: str | None = None) -> str:
    part = f"chunk-{ep // CHUNK:03d}/file-{ep % CHUNK:03d}"
    if kind == "data":
        return f"data/{part}.parquet"
    if kind == "meta":
        return f"meta/episodes/{part}.parquet"
    return f"videos/{key}/{part}.mp4"


def _replace(tmp: Path, final: Path) -> None:
    final.parent.mkdir(parents=True, exist_ok=True)
    os.replace(tmp, final)


def _tmp(final: Path) -> Path:
    final.parent.mkdir(parents=True, exist_ok=True)
    # Not `*.parquet`: LeRobot's loader reads every `*/*.parquet` under `data/` and `meta/episodes/`.
    return final.with_name(f".{final.name}.tmp")


def video_feature(shape: tuple[int, ...], fps: int, codec: str, pix_fmt: str) -> dict:
    h, w, c = shape
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


def _layout_of(info: dict) -> dict:
    """What must match for an append: fps and every feature's dtype and shape."""
    return {
        "fps": info["fps"],
        "features": {k: (f["dtype"], list(f["shape"])) for k, f in info["features"].items()},
    }


def _encode(path: Path, frames: list[np.ndarray], fps: int, codec: str, pix_fmt: str, crf: int) -> None:
    import av

    tmp = _tmp(path)
    h, w = frames[0].shape[:2]
    with av.open(str(tmp), mode="w", format="mp4") as out:
        stream = out.add_stream(codec, rate=fps)
        stream.width, stream.height, stream.pix_fmt = w, h, pix_fmt
        if codec in ("libx264", "libsvtav1", "libaom-av1"):
            stream.options = {"crf": str(crf), "g": "2"}
        for frame in frames:
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")
            out.mux(stream.encode(vf))
        out.mux(stream.encode())
    _replace(tmp, path)


def _column(values: np.ndarray, dtype: str):
    import pyarrow as pa

    arr = np.ascontiguousarray(values)
    if arr.ndim == 1:
        return pa.array(arr, type=pa.from_numpy_dtype(np.dtype(dtype)))
    n = arr.shape[1]
    flat = pa.array(arr.reshape(-1), type=pa.from_numpy_dtype(np.dtype(dtype)))
    return pa.FixedSizeListArray.from_arrays(flat, n)


class DatasetWriter:
    """Appends whole episodes to a LeRobot v3 dataset at `root`."""

    def __init__(
        self,
        root: str | os.PathLike,
        repo_id: str,
        fps: int,
        features: dict[str, dict],
        robot_type: str | None = None,
        codec: str = "libx264",
        pix_fmt: str = "yuv420p",
        crf: int = 18,
    ) -> None:
        self.root = Path(root)
        self.repo_id = repo_id
        self.codec, self.pix_fmt, self.crf = codec, pix_fmt, crf
        self.fps = int(fps)
        full = {**features, **DEFAULT_FEATURES}
        info_path = self.root / "meta" / "info.json"
        if info_path.exists():
            info = json.loads(info_path.read_text())
            self._check_layout(info, full, info_path)
            self.info = info
            self._remove_orphans()
        else:
            self.info = {
                "codebase_version": CODEBASE_VERSION,
                "robot_type": robot_type,
                "total_episodes": 0,
                "total_frames": 0,
                "total_tasks": 0,
                "chunks_size": CHUNK,
                "data_files_size_in_mb": 100,
                "video_files_size_in_mb": 200,
                "fps": self.fps,
                "splits": {},
                "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
                "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
                "features": full,
            }
        self.tasks = self._load_tasks()

    def _check_layout(self, info: dict, full: dict, path: Path) -> None:
        if info.get("codebase_version") != CODEBASE_VERSION:
            raise LayoutError(
                f"`{path}` is a LeRobot dataset of version `{info.get('codebase_version')}`, "
                f"not `{CODEBASE_VERSION}`\nhint: record into a new directory"
            )
        old = _layout_of(info)
        new = _layout_of({"fps": self.fps, "features": full})
        problems = []
        if old["fps"] != new["fps"]:
            problems.append(f"fps `{old['fps']}` there, `{new['fps']}` here")
        for key in sorted(set(old["features"]) | set(new["features"])):
            a, b = old["features"].get(key), new["features"].get(key)
            if a != b:
                problems.append(
                    f"feature `{key}`: {_desc(a)} there, {_desc(b)} here"
                )
        if problems:
            raise LayoutError(
                f"the dataset at `{self.root}` has another layout: " + "; ".join(problems)
                + "\nhint: record into a new directory, or record the same env with the same "
                "settings (observation, action, frames, fps) to append"
            )

    def _remove_orphans(self) -> None:
        """Files of episodes that `info.json` does not count (a crash mid-episode)."""
        done = self.info["total_episodes"]
        for sub in ("data", "meta/episodes", "videos"):
            for f in (self.root / sub).rglob("*"):
                if not f.is_file():
                    continue
                if f.name.startswith("."):
                    f.unlink()
                    continue
                try:
                    chunk = int(f.parent.name.split("-")[1])
                    idx = int(f.stem.split("-")[1])
                except (IndexError, ValueError):
                    continue
                if chunk * CHUNK + idx >= done:
                    f.unlink()

    def _load_tasks(self) -> dict[str, int]:
        path = self.root / "meta" / "tasks.parquet"
        if not path.exists():
            return {}
        import pyarrow.parquet as pq

        table = pq.read_table(path).to_pydict()
        return dict(zip(table["task"], table["task_index"]))

    @property
    def video_keys(self) -> list[str]:
        return [k for k, f in self.info["features"].items() if f["dtype"] == "video"]

    def write_episode(self, columns: dict[str, np.ndarray], videos: dict[str, list], task: str) -> int:
        """Writes one ended episode: `columns` per non-default feature (one row per frame),
        `videos` per video feature (the frames). Returns its episode index."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        ep = self.info["total_episodes"]
        start = self.info["total_frames"]
        n = len(next(iter(columns.values())))
        if task not in self.tasks:
            self.tasks[task] = len(self.tasks)
        task_index = self.tasks[task]
        feats = self.info["features"]

        meta: dict[str, Any] = {}
        for key in self.video_keys:
            _encode(self.root / _rel("video", ep, key), videos[key], self.fps, self.codec, self.pix_fmt, self.crf)
            meta[f"videos/{key}/chunk_index"] = ep // CHUNK
            meta[f"videos/{key}/file_index"] = ep % CHUNK
            meta[f"videos/{key}/from_timestamp"] = 0.0
            meta[f"videos/{key}/to_timestamp"] = n / self.fps

        frame_index = np.arange(n, dtype=np.int64)
        cols = dict(columns)
        cols["timestamp"] = (frame_index / self.fps).astype(np.float32)
        cols["frame_index"] = frame_index
        cols["episode_index"] = np.full(n, ep, dtype=np.int64)
        cols["index"] = frame_index + start
        cols["task_index"] = np.full(n, task_index, dtype=np.int64)
        names = [k for k in feats if feats[k]["dtype"] != "video"]
        table = pa.table({k: _column(cols[k], feats[k]["dtype"]) for k in names})
        data_path = self.root / _rel("data", ep)
        tmp = _tmp(data_path)
        pq.write_table(table, tmp)
        _replace(tmp, data_path)

        meta.update(
            {
                "episode_index": ep,
                "tasks": [task],
                "length": n,
                "data/chunk_index": ep // CHUNK,
                "data/file_index": ep % CHUNK,
                "dataset_from_index": start,
                "dataset_to_index": start + n,
                "meta/episodes/chunk_index": ep // CHUNK,
                "meta/episodes/file_index": ep % CHUNK,
            }
        )
        for key in names:
            if feats[key]["dtype"] in ("string", "bool"):
                continue
            v = np.asarray(cols[key], dtype=np.float64).reshape(n, -1)
            meta[f"stats/{key}/min"] = v.min(0).tolist()
            meta[f"stats/{key}/max"] = v.max(0).tolist()
            meta[f"stats/{key}/mean"] = v.mean(0).tolist()
            meta[f"stats/{key}/std"] = v.std(0).tolist()
            meta[f"stats/{key}/count"] = [n]
        meta_path = self.root / _rel("meta", ep)
        tmp = _tmp(meta_path)
        pq.write_table(pa.Table.from_pylist([meta]), tmp)
        _replace(tmp, meta_path)

        tasks_path = self.root / "meta" / "tasks.parquet"
        tmp = _tmp(tasks_path)
        order = sorted(self.tasks, key=self.tasks.get)
        ttable = pa.table(
            {"task_index": pa.array([self.tasks[t] for t in order], pa.int64()), "task": order}
        )
        # pandas reads `task` back as the index, as LeRobot's loader expects.
        ttable = ttable.replace_schema_metadata(
            {b"pandas": json.dumps(_pandas_meta()).encode()}
        )
        pq.write_table(ttable, tmp)
        _replace(tmp, tasks_path)

        self.info["total_episodes"] = ep + 1
        self.info["total_frames"] = start + n
        self.info["total_tasks"] = len(self.tasks)
        self.info["splits"] = {"train": f"0:{ep + 1}"}
        info_path = self.root / "meta" / "info.json"
        tmp = _tmp(info_path)
        tmp.write_text(json.dumps(self.info, indent=4))
        _replace(tmp, info_path)
        return ep


def _desc(f: tuple | None) -> str:
    return "absent" if f is None else f"`{f[0]}` of shape `{tuple(f[1])}`"


def _pandas_meta() -> dict:
    return {
        "index_columns": ["task"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": None},
        ],
        "creator": {"library": "envhub"},
        "pandas_version": "2.0.0",
    }
