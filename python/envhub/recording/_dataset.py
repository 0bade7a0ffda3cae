"""A LeRobot dataset (v3.0 layout) on disk, appended to in commits, written with pyarrow.

The layout, as LeRobot's writer makes it and its loader reads it:

    meta/info.json                          fps, features, totals, path templates, file sizes
    meta/tasks.parquet                      task text -> task_index
    meta/stats.json                         per-feature statistics over every frame
    meta/episodes/chunk-C/file-F.parquet    one row per episode: length, its data and video
                                            files, its rows in the dataset, its time range in
                                            each video file, its statistics
    data/chunk-C/file-F.parquet             one row per frame, many episodes per file
    videos/KEY/chunk-C/file-F.mp4           a camera's frames, many episodes per file

A commit writes its episodes' rows and frames into new data and video files, named after every
file there, and swaps in the new `meta/` whole (`_durable.py`): no file a committed `meta/`
refers to is ever changed, so LeRobot's loader (which globs `data/`) and `aggregate_datasets`
(which reads the files `meta/` names, whole) see only committed episodes at any instant. Small
files are then joined into LeRobot's sizes (`_files.py`). A crash leaves files no committed
episode refers to; the next open removes them.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import glob
import json
import os
import re
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import _encoding as encoding
from ._durable import Commit, fsync_dir, fsync_file, link_or_copy
from ._encoding import Encoding
from ._files import GROUP_BYTES, PARQUET, Files, Groups, Part, group_rows, join_parquet, to_join
from ._memory import release
from ._spill import Spilled, row_bytes, rows_of, values_of, width_of
from ._stats import NAMES, aggregate, aggregate_all, sliced_stats
from ._video import concatenate, count_frames, pix_fmt
from .errors import DatasetLayoutError, RecordingError

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
#: LeRobot's defaults: a data (and episodes) file, a video file is rolled past this size.
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
#: The index columns, which a commit computes.
INDEX_KEYS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
#: envhub's own folder inside a dataset: the lock and files not yet committed.
PRIVATE = ".envhub"
#: The episodes files' kind (`_files.py`), and their columns' prefix.
EPISODES = "meta/episodes"


@dataclass
class Episode:
    """One ended episode, ready to commit: its columns (one row per frame), its videos
    (encoded files in the private folder), statistics, task and success."""

    length: int
    columns: dict[str, np.ndarray]
    videos: dict[str, Path] = field(default_factory=dict)
    video_stats: dict[str, dict[str, Any]] = field(default_factory=dict)
    task: str = ""
    success: bool | None = None


def _ours(rel: str, template: str) -> bool:
    """Whether `rel` is a name `template` makes (`chunk-000/file-000`, ...)."""
    pattern = re.escape(template)
    for field_ in ("chunk_index", "file_index"):
        pattern = pattern.replace(re.escape("{" + field_ + ":03d}"), r"\d{3,}")
    return re.fullmatch(pattern, rel) is not None


def _fmt(template: str, at: tuple[int, int], **kw: str) -> str:
    return template.format(chunk_index=at[0], file_index=at[1], **kw)


def _acquire(path: Path) -> Any:
    """The lock file at `path`, opened and locked (exclusively), or `None` if another process
    holds it. A lock taken on a file that was meanwhile removed (its holder closing) is taken
    again on the file now there, so two writers never hold locks on two different files."""
    for _ in range(100):
        lock = open(path, "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            return None
        try:
            same = os.stat(path).st_ino == os.fstat(lock.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return lock
        lock.close()
        path.parent.mkdir(exist_ok=True)
    raise RecordingError(f"the lock `{path}` kept being removed while it was taken\nhint: is another program cleaning the folder?")


def _remove_private(private: Path) -> None:
    """Removes the private folder while its lock is still held: everything but the lock, then
    the lock file, then the folder (a writer that locks the removed file sees it is gone)."""
    for p in private.iterdir():
        if p.name != "lock":
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        (private / "lock").unlink()
        private.rmdir()


def _read_only(folder: Path) -> bool:
    """Whether `folder`'s file system is mounted read-only (where `access` does not say so)."""
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _stacked(column: Any) -> np.ndarray:
    """A column of nested lists of numbers (one per row, all of one shape) as an array
    `(rows, *shape)`; `ValueError` if rows differ in shape or hold nulls."""
    import pyarrow as pa

    flat = column.combine_chunks()
    rows = len(flat)
    if flat.null_count:
        raise ValueError("nulls")
    while pa.types.is_list(flat.type) or pa.types.is_large_list(flat.type) or pa.types.is_fixed_size_list(flat.type):
        flat = flat.flatten()
        if flat.null_count:
            raise ValueError("nulls")
    values = flat.to_numpy(zero_copy_only=False).astype(np.float64)
    shape = np.shape(column[0].as_py()) if rows else ()
    return values.reshape(rows, *shape)


def _same_stats(a: dict[str, dict[str, np.ndarray]], b: dict[str, dict[str, Any]]) -> bool:
    """Whether two sets of statistics agree: counts exactly, the rest to rounding (LeRobot's
    `aggregate_stats` differs from these sums by up to 1e-8 relative in `std`)."""
    if set(a) != set(b):
        return False
    for key, stats in a.items():
        for name, value in stats.items():
            other = b[key].get(name)
            if other is None or np.shape(other) != np.shape(value):
                return False
            if not np.allclose(np.asarray(other, dtype=np.float64), value, rtol=1e-6, atol=1e-9):
                return False
    return True


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _nested(values: np.ndarray, leaf: Any) -> Any:
    """`values` of shape `(rows, *dims)` as a pyarrow column of nested lists (one level per
    dim), built from the flat buffer."""
    import pyarrow as pa

    array = pa.array(np.ascontiguousarray(values).reshape(-1), type=leaf)
    for size in reversed(values.shape[1:]):
        offsets = np.arange(0, len(array) + 1, size, dtype=np.int32)
        array = pa.ListArray.from_arrays(pa.array(offsets), array)
    return array


def _layout_problems(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    problems = []
    if old.get("codebase_version") != new["codebase_version"]:
        problems.append(
            f"its version is `{old.get('codebase_version')}`, this recorder writes `{new['codebase_version']}`"
        )
    if old.get("fps") != new["fps"]:
        problems.append(f"fps `{old.get('fps')}` there, `{new['fps']}` here")
    a, b = old.get("features", {}), new["features"]
    for key in [*a, *(k for k in b if k not in a)]:
        fa, fb = a.get(key), b.get(key)
        if fa is None:
            problems.append(f"feature `{key}` is recorded here but absent there")
        elif fb is None:
            problems.append(f"feature `{key}` is there but not recorded here")
        elif (fa["dtype"], list(fa["shape"])) != (fb["dtype"], list(fb["shape"])):
            problems.append(
                f"feature `{key}` is `{fa['dtype']}` of shape {list(fa['shape'])} there, "
                f"`{fb['dtype']}` of shape {list(fb['shape'])} here"
            )
    return problems


def _pandas_tasks_metadata(index_name: str) -> bytes:
    """The pandas metadata that makes `pandas.read_parquet` give the task text as the index,
    as LeRobot's loader expects (`tasks.iloc[i].name`)."""
    return json.dumps(
        {
            "index_columns": [index_name],
            "column_indexes": [
                {"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
                 "metadata": {"encoding": "UTF-8"}}
            ],
            "columns": [
                {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
                 "numpy_type": "int64", "metadata": None},
                {"name": None if index_name.startswith("__") else index_name, "field_name": index_name,
                 "pandas_type": "unicode", "numpy_type": "object", "metadata": None},
            ],
            "creator": {"library": "envhub"},
            "pandas_version": "2.2.0",
        }
    ).encode()


class Dataset:
    """A LeRobot v3.0 dataset folder this process appends to (it holds the folder's lock).

    `features` maps every recorded feature (the index columns included) to its entry in
    `info.json`. An existing dataset must have the same version, fps and features (dtype and
    shape), else `DatasetLayoutError` names each difference."""

    def __init__(self, root: str | os.PathLike, fps: int, features: dict[str, dict], robot_type: str | None,
                 data_files_size_in_mb: float | None = None, video_files_size_in_mb: float | None = None, *,
                 codec: str | None = None, crf: int | None = None, gop: int | None = None) -> None:
        # Fails early, before any file is touched; and loads now what commits use (pyarrow's
        # Parquet, and pandas, which `pa.array` imports where installed: about 50 MiB), so that
        # a recording's memory is the recording's (recording.md's bound is over the process
        # once the dataset is opened).
        import pyarrow as pa
        import pyarrow.parquet

        pa.array(np.zeros(1))

        self.root = Path(root)
        private = self.root / PRIVATE
        self._ours = private.is_dir()  # an envhub recording was here (maybe cut short)
        self._request = (codec, crf, gop)
        wanted = {"codebase_version": CODEBASE_VERSION, "fps": fps, "features": features}
        self._check_writable()
        self._inspect(wanted)  # before anything is created: a refusal touches nothing
        made = [p for p in (self.root, private) if not p.exists()]
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            private.mkdir(exist_ok=True)
            lock = _acquire(private / "lock")
        except OSError as e:
            raise RecordingError(f"cannot write into `{self.root}`: {e}\nhint: record into a folder you can write") from e
        if lock is None:
            raise RecordingError(
                f"the dataset `{self.root}` is being written by another recorder\n"
                "hint: record into another folder, or wait for that recording to end"
            )
        self._lock = lock
        try:
            self._open(fps, features, robot_type,
                       {"data_files_size_in_mb": data_files_size_in_mb,
                        "video_files_size_in_mb": video_files_size_in_mb})
        except BaseException:
            # Refused under the lock (another process changed the folder meanwhile): what this
            # opening made goes, the lock last.
            shutil.rmtree(private / "staging", ignore_errors=True)
            if private in made:
                _remove_private(private)
            lock.close()
            if self.root in made:
                with contextlib.suppress(OSError):
                    self.root.rmdir()
            raise

    def _check_writable(self) -> None:
        """A clear error for a dangling link, a file, or a folder this process cannot write."""
        if self.root.is_symlink() and not self.root.exists():
            raise DatasetLayoutError(
                f"`{self.root}` is a symbolic link to `{os.readlink(self.root)}`, which does not exist\n"
                "hint: create the folder it points to, or record into another folder"
            )
        if self.root.exists() and not self.root.is_dir():
            raise DatasetLayoutError(f"`{self.root}` is a file\nhint: record into a new or empty folder")
        folder = self.root
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK) or _read_only(folder):
            raise RecordingError(
                f"`{folder}` is not writable by this process, so the dataset `{self.root}` cannot be "
                "written there\nhint: record into a folder you can write (check its permissions, or "
                "whether its file system is mounted read-only)"
            )

    def _inspect(self, wanted: dict[str, Any], locked: bool = False) -> None:
        """Every check of the folder, reading only: its layout, its committed episodes, and the
        encoding of each camera (the dataset's, or the one asked for a new dataset). Sets
        `info` (`None` for a new folder), `_rows` and `encodings`."""
        info = self._check_folder(wanted, locked)
        self.info = info  # type: ignore[assignment]
        features = (info or wanted)["features"]
        self.video_keys = [k for k, f in features.items() if f["dtype"] == "video"]
        self._rows = self._committed_episode_rows() if info is not None else []
        self.encodings = self._encodings(features, (info or wanted)["fps"])

    def _encodings(self, features: dict[str, dict], fps: int) -> dict[str, Encoding]:
        """Each camera's encoding: the dataset's where it has videos (asked parameters must be
        the same, and two frames encoded with them must join its last file), else the asked
        one, with the codec `info.json` names."""
        import av

        codec, crf, gop = self._request
        last = self._rows[-1] if self._rows else {}
        out: dict[str, Encoding] = {}
        for key in self.video_keys:
            f = features[key]
            if last.get(f"videos/{key}/chunk_index") is not None:
                at = (last[f"videos/{key}/chunk_index"], last[f"videos/{key}/file_index"])
                path = self.root / _fmt(VIDEO_PATH, at, video_key=key)
                try:
                    there = encoding.read(path, f)
                    problems = encoding.conflicts(there, codec, crf, gop)
                    if not problems and there.encoder not in av.codecs_available:
                        problems = [f"its videos are encoded with `{there.encoder}`, which this PyAV build lacks"]
                    if not problems:
                        encoding.check_joinable(path, there, fps)
                except (ValueError, OSError, av.FFmpegError) as e:
                    problems = [str(e)]
                if problems:
                    raise DatasetLayoutError(
                        f"the dataset at `{self.root}` cannot take this recording's `{key}` frames in its "
                        f"own encoding: {'; '.join(problems)}\nhint: leave `codec`, `crf` and `gop` out to "
                        "append in the dataset's encoding, or record into a new folder"
                    )
                out[key] = there
                continue
            h, w, _ = f["shape"]
            info = f.get("info", {})
            named = info.get("video.codec")
            chosen = codec or encoding.ENCODER.get(named or "")
            if named and chosen and encoding.CANONICAL.get(chosen) != named:
                raise DatasetLayoutError(
                    f"the dataset at `{self.root}` says its `{key}` videos are `{named}`, this recording "
                    f"encodes `{encoding.CANONICAL.get(chosen)}` (`{chosen}`)\nhint: leave `codec` out"
                )
            out[key] = encoding.requested(chosen, crf, gop, info.get("video.pix_fmt") or pix_fmt(w, h), w, h)
        return out

    def _check_folder(self, wanted: dict[str, Any], locked: bool = False) -> dict[str, Any] | None:
        """The dataset's `info.json` if it holds one of this layout, `None` for a new or empty
        folder (or one where an envhub recording crashed before its first commit); else
        `DatasetLayoutError`. Reads only."""
        info_path = self.root / "meta" / "info.json"
        if info_path.exists():
            try:
                info = json.loads(info_path.read_text())
            except (OSError, ValueError) as e:
                raise DatasetLayoutError(
                    f"`{info_path}` cannot be read as JSON ({e})\nhint: record into a new folder"
                ) from e
            problems = _layout_problems(info, wanted)
            if problems:
                raise DatasetLayoutError(
                    f"the dataset at `{self.root}` has another layout than this recording: "
                    + "; ".join(problems)
                    + "\nhint: record into a new folder, or record the same env with the same "
                    "observation, action, frames and fps to append to this one"
                )
            return info
        if not self.root.exists():
            return None
        # Without `info.json`, `data/`, `meta/` and `videos/` are what a crash in the first
        # commit left, if envhub was recording here; anything else is not ours.
        ours = (PRIVATE, "data", "meta", "videos") if self._ours else (PRIVATE,) if locked else ()
        others = [p.name for p in self.root.iterdir() if p.name not in ours]
        if others:
            raise DatasetLayoutError(
                f"`{self.root}` is not empty and holds no LeRobot dataset (no `meta/info.json`; "
                f"it has {', '.join(f'`{n}`' for n in sorted(others)[:5])})\n"
                "hint: record into a new or empty folder"
            )
        return None

    def _open(self, fps: int, features: dict[str, dict], robot_type: str | None,
              sizes: dict[str, float | None]) -> None:
        wanted = {"codebase_version": CODEBASE_VERSION, "fps": fps, "features": features}
        self._inspect(wanted, locked=True)  # again, under the lock
        info = self.info
        self.staging = self.root / PRIVATE / "staging"
        shutil.rmtree(self.staging, ignore_errors=True)
        self.staging.mkdir()
        if info is None:
            self.info = {
                "codebase_version": CODEBASE_VERSION,
                "robot_type": robot_type,
                "total_episodes": 0,
                "total_frames": 0,
                "total_tasks": 0,
                "chunks_size": CHUNKS_SIZE,
                "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
                "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
                "fps": fps,
                "splits": {},
                "data_path": DATA_PATH,
                "video_path": VIDEO_PATH if any(f["dtype"] == "video" for f in features.values()) else None,
                "features": features,
            }
        self.features = self.info["features"]
        for key, value in sizes.items():
            if value is not None:
                self.info[key] = value
        rows = self._rows
        self._remove_uncommitted(rows)
        self._joins = True  # until a commit finds no atomic exchange (`_join`)
        self._files = {"data": Files("data", DATA_PATH, self.info["data_files_size_in_mb"], video=False)}
        for k in self.video_keys:
            self._files[k] = Files(k, VIDEO_PATH.replace("{video_key}", k), self.info["video_files_size_in_mb"],
                                   video=True)
        # Last, so that its joins come after those that rewrite its files (`_repoint`).
        self._files[EPISODES] = Files(EPISODES, EPISODES_PATH, self.info["data_files_size_in_mb"], video=False)
        for files in self._files.values():
            self._find_run(rows, files)
        self._trim()
        self.tasks = self._read_tasks()
        self.stats = self._committed_stats()
        self._schemas = self._existing_schemas()

    # Reading what is there -----------------------------------------------------------------

    def _episode_files(self) -> list[Path]:
        return sorted((self.root / "meta" / "episodes").glob("*/*.parquet"))

    def _committed_episode_rows(self) -> list[dict[str, Any]]:
        """The rows of `meta/episodes` of the episodes `info.json` counts."""
        import pyarrow.parquet as pq

        total = self.info["total_episodes"]
        keep = ["episode_index", "length", "dataset_from_index", "dataset_to_index", "data/chunk_index",
                "data/file_index", "meta/episodes/chunk_index", "meta/episodes/file_index"]
        for k in self.video_keys:
            keep += [f"videos/{k}/chunk_index", f"videos/{k}/file_index", f"videos/{k}/to_timestamp"]
        rows: list[dict[str, Any]] = []
        for path in self._episode_files():
            names = pq.read_schema(path).names
            table = pq.read_table(path, columns=[c for c in keep if c in names])
            rows += [r for r in table.to_pylist() if r["episode_index"] < total]
        rows.sort(key=lambda r: r["episode_index"])
        if len(rows) != total:
            raise DatasetLayoutError(
                f"the dataset at `{self.root}` counts {total} episodes in `meta/info.json` but "
                f"`meta/episodes/` describes {len(rows)} of them\nhint: record into a new folder"
            )
        return rows

    def _remove_uncommitted(self, rows: list[dict[str, Any]]) -> None:
        """Removes files of `data/`, `meta/episodes/` and `videos/` that no counted episode
        refers to: what a crash between a commit's first rename and `info.json` left."""
        used = {Path(_fmt(DATA_PATH, (r["data/chunk_index"], r["data/file_index"]))) for r in rows}
        used |= {Path(_fmt(EPISODES_PATH, (r["meta/episodes/chunk_index"], r["meta/episodes/file_index"])))
                 for r in rows}
        for k in self.video_keys:
            used |= {Path(_fmt(VIDEO_PATH, (r[f"videos/{k}/chunk_index"], r[f"videos/{k}/file_index"]),
                               video_key=k)) for r in rows}
        removed = []
        # Only names this recorder writes: other files are the user's, left alone.
        patterns = [("data/*/*.parquet", DATA_PATH), ("meta/episodes/*/*.parquet", EPISODES_PATH)]
        patterns += [(f"videos/{glob.escape(k)}/*/*.mp4", VIDEO_PATH.replace("{video_key}", k))
                     for k in self.video_keys]
        for pattern, template in patterns:
            for path in self.root.glob(pattern):
                rel = path.relative_to(self.root)
                if rel not in used and _ours(str(rel), template):
                    path.unlink()
                    removed.append(str(rel))
        if removed:
            warnings.warn(
                f"removed {len(removed)} file(s) of episodes that a crash left uncommitted in "
                f"`{self.root}`: {', '.join(sorted(removed)[:5])}{' ...' if len(removed) > 5 else ''}",
                stacklevel=4,
            )

    def _find_run(self, rows: list[dict[str, Any]], files: Files) -> None:
        """The run of `files` the committed episodes leave: the newest files that together stay
        under the kind's size (the last one always), with their rows or frames and episodes."""
        prefix, fps = files.prefix(), self.info["fps"]
        parts: list[Part] = []
        for r in rows:
            chunk = r.get(f"{prefix}/chunk_index")
            if chunk is None:
                return
            at = (int(chunk), int(r[f"{prefix}/file_index"]))
            if not parts or parts[-1].at != at:
                parts.append(Part(at, 0, 0, int(r["episode_index"]), 0))
            part = parts[-1]
            part.episodes += 1
            if files.video:
                part.count = round(float(r[f"{prefix}/to_timestamp"]) * fps)
            else:
                part.count += 1 if files.kind == EPISODES else int(r["length"])
        if not parts:
            return
        files.last = parts[-1].at
        total = 0
        for part in reversed(parts):
            part.size = os.path.getsize(self.root / files.rel(part.at))
            total += part.size
            if files.run and total / 2**20 >= files.limit_mb:
                break
            files.run.insert(0, part)

    def _trim(self) -> None:
        """Cuts what a crash left appended to the last data and video files (rows and frames
        past the last commit: recorders before this one appended to them), so the files hold
        exactly what `meta/` describes."""
        import pyarrow.parquet as pq

        cut = []
        for key, files in self._files.items():
            if not files.run:
                continue
            last = files.run[-1]
            path = self.root / files.rel(last.at)
            if not files.video:
                if pq.read_metadata(path).num_rows > last.count:
                    tmp = self.staging / "trim.parquet"
                    self._write_table(pq.read_table(path).slice(0, last.count), tmp)
                    cut.append((tmp, path, files, last))
            elif count_frames(path) > last.count:
                tmp = self.staging / f"trim-{len(cut)}.mp4"
                concatenate([(path, last.count)], tmp, self.info["fps"], self.encodings[key].tag())
                cut.append((tmp, path, files, last))
        for tmp, path, _, last in cut:
            fsync_file(tmp)
            os.replace(tmp, path)
            fsync_dir(path.parent)
            last.size = os.path.getsize(path)
        if cut:
            warnings.warn(
                f"cut what a crash left past the last commit from {len(cut)} file(s) of `{self.root}`",
                stacklevel=4,
            )

    def _read_tasks(self) -> dict[str, int]:
        import pyarrow.parquet as pq

        path = self.root / "meta" / "tasks.parquet"
        if not path.exists():
            return {}
        table = pq.read_table(path)
        meta = json.loads((table.schema.metadata or {}).get(b"pandas", b"{}"))
        index = (meta.get("index_columns") or ["task"])[0]
        name = index if isinstance(index, str) and index in table.column_names else "task"
        return dict(zip(table.column(name).to_pylist(), table.column("task_index").to_pylist(), strict=True))

    def _read_stats(self) -> dict[str, dict[str, np.ndarray]]:
        path = self.root / "meta" / "stats.json"
        if not path.exists():
            return {}
        return {k: {s: np.asarray(v) for s, v in d.items()} for k, d in json.loads(path.read_text()).items()}

    def _committed_stats(self) -> dict[str, dict[str, np.ndarray]]:
        """The dataset's statistics over the committed episodes, aggregated from theirs in
        `meta/episodes/` (the commit's own record), and `stats.json` rewritten if it says
        otherwise: without an atomic exchange of `meta/`, a crash between its renames can leave
        a `stats.json` of episodes never committed."""
        import pyarrow.parquet as pq

        written = self._read_stats()
        total = self.info["total_episodes"]
        per_key: dict[str, dict[str, list[np.ndarray]]] = {}
        try:
            for path in self._episode_files():
                names = [n for n in pq.read_schema(path).names if n.startswith("stats/") or n == "episode_index"]
                table = pq.read_table(path, columns=names)
                keep = table.column("episode_index").to_numpy() < total
                for name in names:
                    if name != "episode_index":
                        key, stat = name[len("stats/"):].rsplit("/", 1)
                        per_key.setdefault(key, {}).setdefault(stat, []).append(_stacked(table.column(name))[keep])
        except ValueError:  # statistics with gaps (nulls): `stats.json` is all there is
            return written
        stats: dict[str, dict[str, np.ndarray]] = {}
        for key, parts in per_key.items():
            columns = {stat: np.concatenate(values) for stat, values in parts.items()}
            if not {"min", "max", "mean", "std", "count"} <= set(columns) or len(columns["count"]) != total:
                return written  # episodes without their statistics: `stats.json` is all there is
            stats[key] = aggregate_all(columns)
        if total and not _same_stats(stats, written):
            tmp = self.staging / "stats.json"
            self._write_json({k: {s: np.asarray(v).tolist() for s, v in d.items()} for k, d in stats.items()}, tmp)
            fsync_file(tmp)
            os.replace(tmp, self.root / "meta" / "stats.json")
            fsync_dir(self.root / "meta")
            warnings.warn(f"`{self.root}/meta/stats.json` did not describe the committed episodes: rewritten",
                          stacklevel=4)
        return stats if total else written

    def _existing_schemas(self) -> dict[str, Any]:
        """The schemas of the files already there, which new files follow (the loader reads
        all files of a folder as one table)."""
        import pyarrow.parquet as pq

        out: dict[str, Any] = {}
        data = sorted((self.root / "data").glob("*/*.parquet"))
        if data:
            out["data"] = pq.read_schema(data[-1])
        episodes = self._episode_files()
        if episodes:
            out["episodes"] = pq.read_schema(episodes[-1])
        return out

    # Writing -------------------------------------------------------------------------------

    def staged(self, name: str) -> Path:
        """A path in the private folder, for a file not committed yet."""
        return self.staging / name

    @staticmethod
    def _write_table(table: Any, path: Path) -> None:
        import pyarrow.parquet as pq

        pq.write_table(table, path, row_group_size=group_rows(table), **PARQUET)

    @staticmethod
    def _write_json(data: dict[str, Any], path: Path) -> None:
        with open(path, "w") as f:
            json.dump(data, f, indent=4, ensure_ascii=False)

    def commit(self, episodes: list[Episode]) -> list[int]:
        """Writes `episodes` into the dataset in one commit; returns their episode indices.
        On an error nothing is committed and the dataset's state here is as before."""
        if not episodes:
            return []
        for key, files in self._files.items():  # LeRobot's roll: the run joined, the next file new
            if files.video:
                adding = sum(os.path.getsize(ep.videos[key]) for ep in episodes)
            else:  # at the run's bytes per row (frame, or episode)
                rows = len(episodes) if key == EPISODES else sum(ep.length for ep in episodes)
                adding = sum(p.size for p in files.run) * rows // max(sum(p.count for p in files.run), 1)
            if files.rolls(adding):
                self._join(files, 0)
                files.run = []
        tasks, stats = dict(self.tasks), dict(self.stats)
        try:
            indices = self._commit(episodes)
        except BaseException:
            self.tasks, self.stats = tasks, stats
            raise
        for files in self._files.values():
            first = to_join([p.size for p in files.run])
            self._join(files, self._aligned(files, first) if files.kind == EPISODES else first)
        return indices

    def _aligned(self, episodes: Files, first: int) -> int:
        """The first of the episodes files to join from `first` on, moved on until the joined
        file holds no episodes of two files of a data or video run. A data or video join
        re-points its episodes by rewriting every episodes file that holds one of them, so an
        episodes file across such a boundary would be rewritten whole by a join that moves a
        part of it: a cost that grew with the episodes files (up to 16 MiB each between
        rolls), so with the commits, not with the join. Kept so, an episodes file lies inside
        one file of each run, and a join rewrites exactly the episodes it moves. (A roll or the
        close joins a run whole, as LeRobot's files are.)"""
        bounds = {p.first for kind, files in self._files.items() if kind != EPISODES for p in files.run}
        end = episodes.run[-1].first + episodes.run[-1].episodes if episodes.run else 0
        while first < len(episodes.run) - 1 and any(episodes.run[first].first < b < end for b in bounds):
            first += 1
        return first

    # Joining small files (`_files.py`) -----------------------------------------------------

    def _join(self, files: Files, first: int) -> None:
        """Joins the run's files from `first` on into one, at the first one's name: a new file
        after every file there, `meta/` swapped to it, the joined files removed, then the new
        file linked to the first one's name and `meta/` swapped again. On an error (a full
        disk) the run stays as it was, with a warning: the joins are an optimisation."""
        parts = files.run[first:]
        if len(parts) < 2 or not self._joins:
            # Without an atomic exchange, a crash inside a join's `meta/` change would leave
            # some episodes pointing at the joined file and others at the files it joined.
            return
        commits: list[Commit] = []
        try:
            self._join_parts(commits, files, first, parts)
        except OSError as e:  # a full disk (PyAV's I/O errors are `OSError`s too)
            for commit in commits:
                commit.discard()
            warnings.warn(f"could not join {len(parts)} `{files.kind}` files of `{self.root}` ({e}); "
                          "they stay as they are", stacklevel=4)

    def _join_parts(self, commits: list[Commit], files: Files, first: int, parts: list[Part]) -> None:
        if files.kind == EPISODES:
            self._join_episodes(commits, files, first, parts)
            return
        target = files.after_last(CHUNKS_SIZE)
        commit = Commit(self.root, self.staging)
        commits.append(commit)
        paths = [self.root / files.rel(p.at) for p in parts]
        if files.video:
            tmp = commit.staged("joined.mp4")
            concatenate([(path, p.count) for path, p in zip(paths, parts, strict=True)], tmp, self.info["fps"],
                        self.encodings[files.kind].tag())
        else:
            tmp = commit.staged("joined.parquet")
            join_parquet(paths, tmp)
        commit.place(tmp, files.rel(target))
        shifts = np.concatenate([[0], np.cumsum([p.count for p in parts])[:-1]])
        self._repoint(commit, files, parts, target, shifts)
        commit.apply()
        joined = Part(target, sum(p.count for p in parts), os.path.getsize(self.root / files.rel(target)),
                      parts[0].first, sum(p.episodes for p in parts))
        files.run[first:] = [joined]
        files.last = target
        for path in paths:
            path.unlink()
        for folder in {path.parent for path in paths}:
            fsync_dir(folder)
        # Back to the first joined file's name, so that names stay consecutive.
        home = parts[0].at
        commit = Commit(self.root, self.staging)
        commits.append(commit)
        tmp = commit.staged("link")
        link_or_copy(str(self.root / files.rel(target)), str(tmp))
        commit.place(tmp, files.rel(home))
        self._repoint(commit, files, [joined], home, np.zeros(1, np.int64))
        commit.apply()
        (self.root / files.rel(target)).unlink()
        fsync_dir((self.root / files.rel(target)).parent)
        joined.at = files.last = home

    def _join_episodes(self, commits: list[Commit], files: Files, first: int, parts: list[Part]) -> None:
        """Episodes files are in `meta/`, which changes whole: the joined file replaces the
        first one, the others go, in one swap (or, without an atomic exchange, the joined file
        first, so LeRobot's loader, which takes the glob's row `e` as episode `e`, reads the
        committed episodes in order at every step)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        commit = Commit(self.root, self.staging)
        commits.append(commit)
        home = parts[0].at
        paths = [self.root / files.rel(p.at) for p in parts]
        out = commit.meta_file(files.rel(home)[len("meta/"):])
        schema = pq.read_schema(paths[0])
        with pq.ParquetWriter(out, schema, **PARQUET) as writer:
            groups = Groups(writer)
            for path in paths:
                f = pq.ParquetFile(path)
                for g in range(f.num_row_groups):
                    table = f.read_row_group(g, use_threads=False).cast(schema)
                    for name, value in (("meta/episodes/chunk_index", home[0]), ("meta/episodes/file_index", home[1])):
                        i = schema.get_field_index(name)
                        table = table.set_column(i, schema.field(i), pa.array(np.full(len(table), value)).cast(schema.field(i).type))
                    groups.write(table)
                    del table
            groups.flush()
        for p in parts[1:]:
            commit.remove_meta_file(files.rel(p.at)[len("meta/"):])
        commit.apply()
        files.run[first:] = [Part(home, sum(p.count for p in parts), os.path.getsize(self.root / files.rel(home)),
                                  parts[0].first, sum(p.episodes for p in parts))]
        files.last = home

    def _repoint(self, commit: Commit, files: Files, parts: list[Part], at: tuple[int, int],
                 shifts: np.ndarray) -> None:
        """Writes into `commit`'s `meta/` the episodes files with the episodes of `parts`
        pointing at the file `at`, where part `k` starts `shifts[k]` frames in. Row group by
        row group (an episodes file grows to 100 MB), written in groups of about
        `GROUP_BYTES` (`Groups`)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        start, end = parts[0].first, parts[-1].first + parts[-1].episodes
        shift = np.repeat(np.asarray(shifts, dtype=np.int64), [p.episodes for p in parts])
        prefix, fps = files.prefix(), self.info["fps"]
        for path in reversed(self._episode_files()):
            source = pq.ParquetFile(path)
            index = source.read(columns=["episode_index"], use_threads=False).column(0).to_numpy()
            if ((index >= start) & (index < end)).any():
                out = commit.meta_file(str(path.relative_to(self.root / "meta")))
                with pq.ParquetWriter(out, source.schema_arrow, **PARQUET) as writer:
                    groups = Groups(writer)
                    for g in range(source.num_row_groups):
                        table = source.read_row_group(g, use_threads=False)
                        rows = table.column("episode_index").to_numpy()
                        chosen = (rows >= start) & (rows < end)
                        moved = np.where(chosen, shift[np.clip(rows - start, 0, len(shift) - 1)], 0)
                        new = {f"{prefix}/chunk_index": np.where(chosen, at[0], table.column(f"{prefix}/chunk_index")),
                               f"{prefix}/file_index": np.where(chosen, at[1], table.column(f"{prefix}/file_index"))}
                        if files.video:
                            for name in ("from_timestamp", "to_timestamp"):
                                old = table.column(f"{prefix}/{name}").to_numpy()
                                new[f"{prefix}/{name}"] = np.where(moved != 0, (np.round(old * fps) + moved) / fps, old)
                        for name, values in new.items():
                            i = table.schema.get_field_index(name)
                            table = table.set_column(i, table.schema.field(i),
                                                     pa.array(values).cast(table.schema.field(i).type))
                        groups.write(table)
                        del table
                    groups.flush()
            if len(index) and index.min() <= start:
                break

    def _commit(self, episodes: list[Episode]) -> list[int]:
        """Writes `episodes` into the dataset (see the module's doc for the order); returns
        their episode indices. Statistics are computed over all of them at once (one
        `reduceat` per column and statistic), since commits of many episodes are common."""
        import pyarrow.parquet as pq

        first_ep, first_frame = self.info["total_episodes"], self.info["total_frames"]
        new_tasks = [e.task for e in episodes if e.task not in self.tasks]
        for task in dict.fromkeys(new_tasks):
            self.tasks[task] = len(self.tasks)
        fps = self.info["fps"]
        commit = Commit(self.root, self.staging)
        count = len(episodes)
        lengths = np.array([ep.length for ep in episodes], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        total = int(lengths.sum())
        task_index = np.array([self.tasks[ep.task] for ep in episodes], dtype=np.int64)
        keys = [k for k, f in self.features.items() if f["dtype"] != "video" and k not in INDEX_KEYS]

        def rows(key: str, lo: int, hi: int) -> np.ndarray:
            """Rows `lo..hi` of the commit's column `key`: episodes' columns, in memory or
            spilled (`_spill.py`), are read a row group or a statistics' slice at a time."""
            at = np.arange(lo, hi, dtype=np.int64)
            ep = np.searchsorted(starts, at, "right") - 1
            if key == "timestamp":
                return ((at - starts[ep]) / fps).astype(np.float32)
            if key == "frame_index":
                return at - starts[ep]
            if key == "episode_index":
                return first_ep + ep
            if key == "index":
                return first_frame + at
            if key == "task_index":
                return task_index[ep]
            return _joined([rows_of(episodes[e].columns[key], max(lo, starts[e]) - starts[e],
                                    min(hi, starts[e] + lengths[e]) - starts[e]) for e in range(ep[0], ep[-1] + 1)])

        # Data and videos: new files, after every file there, that only the new `meta/` refers
        # to (`_files.py`); an episode is a range of rows and a time range of its files.
        data_files = self._files["data"]
        data_at = data_files.after_last(CHUNKS_SIZE)
        data = commit.staged("data.parquet")
        row = 8 * len(INDEX_KEYS) + sum(row_bytes(episodes[0].columns[k]) for k in keys)
        group = max(1, GROUP_BYTES // row)
        with contextlib.ExitStack() as stack:
            writer = None
            for lo in range(0, total, group):
                table = self._data_table({k: rows(k, lo, min(lo + group, total)) for k in [*keys, *INDEX_KEYS]})
                if writer is None:
                    writer = stack.enter_context(pq.ParquetWriter(data, table.schema, **PARQUET))
                writer.write_table(table)
                del table
                release()
        commit.place(data, data_files.rel(data_at))
        meta: dict[str, Any] = {
            "episode_index": np.arange(first_ep, first_ep + count, dtype=np.int64),
            "tasks": [[ep.task] for ep in episodes],
            "length": lengths,
            "data/chunk_index": np.full(count, data_at[0]),
            "data/file_index": np.full(count, data_at[1]),
            "dataset_from_index": first_frame + starts,
            "dataset_to_index": first_frame + starts + lengths,
        }
        placed = {"data": (data_at, total, data)}
        for key in self.video_keys:
            files = self._files[key]
            at = files.after_last(CHUNKS_SIZE)
            video = commit.staged("video.mp4")  # packets copied, not encoded again
            concatenate([(ep.videos[key], ep.length) for ep in episodes], video, fps, self.encodings[key].tag())
            commit.place(video, files.rel(at))
            meta[f"videos/{key}/chunk_index"] = np.full(count, at[0])
            meta[f"videos/{key}/file_index"] = np.full(count, at[1])
            meta[f"videos/{key}/from_timestamp"] = starts / fps
            meta[f"videos/{key}/to_timestamp"] = (starts + lengths) / fps
            placed[key] = (at, total, video)
        sizes = {key: os.path.getsize(path) for key, (_, _, path) in placed.items()}
        meta_at = self._files[EPISODES].after_last(CHUNKS_SIZE)
        meta["meta/episodes/chunk_index"] = np.full(count, meta_at[0])
        meta["meta/episodes/file_index"] = np.full(count, meta_at[1])
        def values(key: str, d0: int, d1: int) -> np.ndarray:
            """Values `d0..d1` of every row of the commit's column `key`."""
            if key in INDEX_KEYS:
                return rows(key, 0, total)[:, None]
            return _joined([values_of(ep.columns[key], d0, d1) for ep in episodes])

        for key in [*keys, *INDEX_KEYS]:
            width = 1 if key in INDEX_KEYS else width_of(episodes[0].columns[key])
            per_episode, whole = sliced_stats(functools.partial(values, key), total, width, starts, lengths)
            self.stats[key] = aggregate(self.stats.get(key), whole)
            for name, value in per_episode.items():
                meta[f"stats/{key}/{name}"] = value
        for key in self.video_keys:
            for ep in episodes:
                self.stats[key] = aggregate(self.stats.get(key), ep.video_stats[key])
            for name in NAMES:
                meta[f"stats/{key}/{name}"] = np.stack([ep.video_stats[key][name] for ep in episodes])
        meta["success"] = [ep.success for ep in episodes]

        # A new episodes file too (LeRobot's loader takes the glob's row `e` as episode `e`).
        episodes_file = commit.meta_file(_fmt(EPISODES_PATH, meta_at)[len("meta/"):])
        self._write_table(self._episodes_table(meta), episodes_file)
        placed[EPISODES] = (meta_at, count, episodes_file)
        sizes[EPISODES] = os.path.getsize(episodes_file)
        if new_tasks:
            self._write_tasks(commit.meta_file("tasks.parquet"))
        self._write_json({k: {s: np.asarray(v).tolist() for s, v in d.items()} for k, d in self.stats.items()},
                         commit.meta_file("stats.json"))
        info = dict(self.info)
        info["total_episodes"] = first_ep + count
        info["total_frames"] = first_frame + total
        info["total_tasks"] = len(self.tasks)
        info["splits"] = {"train": f"0:{info['total_episodes']}"}
        self._write_json(info, commit.meta_file("info.json"))
        commit.apply()  # the commit point: `meta/` swapped in whole
        self._joins = self._joins and commit.exchanged
        self.info = info
        for key, (at, frames, _) in placed.items():
            files = self._files[key]
            files.run.append(Part(at, frames, sizes[key], first_ep, count))
            files.last = at
        for ep in episodes:  # now copied into the dataset's files
            for path in ep.videos.values():
                path.unlink(missing_ok=True)
            for column in ep.columns.values():
                if isinstance(column, Spilled):
                    column.spill.remove()
        return list(range(first_ep, first_ep + count))

    def _data_table(self, columns: dict[str, np.ndarray]) -> Any:
        import pyarrow as pa

        arrays, names = [], []
        for key, f in self.features.items():
            if f["dtype"] == "video":
                continue
            values = columns[key]
            dtype = pa.from_numpy_dtype(np.dtype(f["dtype"]))
            if list(f["shape"]) == [1]:
                arrays.append(pa.array(values.reshape(-1), type=dtype))
            else:
                width = int(f["shape"][0])
                flat = pa.array(np.ascontiguousarray(values).reshape(-1), type=dtype)
                arrays.append(pa.FixedSizeListArray.from_arrays(flat, width))
            names.append(key)
        table = pa.Table.from_arrays(arrays, names=names)
        return self._conform(table, "data")

    def _episodes_table(self, meta: dict[str, Any]) -> Any:
        import pyarrow as pa

        arrays, names = [], []
        for key, values in meta.items():
            if key == "tasks":
                array = pa.array(values, type=pa.list_(pa.string()))
            elif key == "success":
                array = pa.array(values, type=pa.bool_())
            elif key.startswith("stats/"):
                array = _nested(np.asarray(values), pa.int64() if key.endswith("/count") else pa.float64())
            elif key.endswith("_timestamp"):
                array = pa.array(np.asarray(values, dtype=np.float64))
            else:
                array = pa.array(np.asarray(values, dtype=np.int64))
            arrays.append(array)
            names.append(key)
        return self._conform(pa.Table.from_arrays(arrays, names=names), "episodes")

    def _conform(self, table: Any, kind: str) -> Any:
        """`table` in the schema of the dataset's existing files of this kind, if any: columns
        they lack are dropped, columns they have and this lacks are null."""
        import pyarrow as pa

        schema = self._schemas.get(kind)
        if schema is None:
            self._schemas[kind] = table.schema
            return table
        columns = []
        for f in schema:
            if f.name in table.column_names:
                columns.append(table.column(f.name).cast(f.type))
            else:
                columns.append(pa.nulls(len(table), type=f.type))
        return pa.Table.from_arrays(columns, schema=schema)

    def _write_tasks(self, path: Path) -> None:
        import pyarrow as pa

        order = sorted(self.tasks, key=self.tasks.__getitem__)
        table = pa.table({"task_index": pa.array([self.tasks[t] for t in order], pa.int64()),
                          "task": pa.array(order, pa.string())})
        table = table.replace_schema_metadata({b"pandas": _pandas_tasks_metadata("task")})
        self._write_table(table, path)

    def close(self) -> None:
        """Releases the folder (removing the private folder's files not committed)."""
        if self._lock.closed:
            return
        try:
            for files in getattr(self, "_files", {}).values():  # each run into one file, as LeRobot's
                self._join(files, 0)
        except Exception as e:  # the committed episodes are whole either way
            warnings.warn(f"could not join the last files of `{self.root}`: {e}", stacklevel=2)
        try:
            _remove_private(self.root / PRIVATE)
        finally:
            self._lock.close()  # released only once the private folder is gone
