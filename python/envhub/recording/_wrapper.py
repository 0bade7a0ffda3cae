"""`RecordEpisodes`: a Gymnasium vector wrapper that writes every env's ended episodes into a
LeRobot dataset, off the stepping thread.

The step path only copies what the step returned (the caller may change arrays in place, and
envhub's are views of shared memory) and puts it on a bounded queue; the writer thread
(`_writer.py`) does everything else.
"""

from __future__ import annotations

import time
import warnings
import weakref
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from ..wire.cores import usable_cores
from ._budget import DEFAULT_QUEUE_BYTES
from ._dataset import Dataset
from ._encoding import CANONICAL, DEFAULT_CODEC
from ._features import RENDER_KEY, STEP_COLUMNS, action_column, features, frame_rate, observation_columns
from ._video import check_codec
from ._writer import STOP, Reset, Step, Writer
from .errors import QueueFullWarning, RecordingError, require


def _mode(env: VectorEnv) -> AutoresetMode:
    mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
    if isinstance(mode, AutoresetMode):
        return mode
    for m in AutoresetMode:
        if str(mode).lower().replace("_", "") == m.value.lower():
            return m
    return AutoresetMode.NEXT_STEP


def _success(info: dict[str, Any], i: int, same_step: bool) -> bool | None:
    """Env `i`'s `success` / `is_success` info at the end of its episode (`None`: it reports
    none). Under `same_step` autoreset the final step's info is `info["final_info"]`."""
    sources = []
    if same_step and isinstance(info.get("final_info"), dict):
        sources.append(info["final_info"])
    sources.append(info)
    for source in sources:
        for key in ("success", "is_success"):
            if key not in source:
                continue
            mask = source.get(f"_{key}")
            if mask is not None and not np.asarray(mask)[i]:
                continue
            return bool(np.asarray(source[key])[i])
    return None


class RecordEpisodes(VectorWrapper):
    """Records the episodes of every env of `env` into the LeRobot dataset (v3.0) at `root`,
    created or appended to.

    Frame `t` of an episode holds the observation the policy saw, the action taken, and what
    that step returned (`next.reward`, `next.done`, `next.terminated`, `next.truncated`);
    timestamps are `t / fps` (`fps`: the env's `render_fps` unless given). A plain
    observation is `observation.state`; a Dict observation's camera images (uint8
    `(h, w, 3)`) become videos `observation.images.<key>` and its other entries
    `observation.<key>`. With `video=True` and an env made with `render_mode="rgb_array"`,
    `render()` frames become the video `observation.images.render`. The task text is `task`,
    else the catalog entry's description (envhub envs), else the env's id.

    The files are LeRobot v3's: data, episodes-metadata and video files holding many episodes,
    each rolled to the next file when it would reach `data_files_size_in_mb` (100, LeRobot's
    default; the episodes files too) or `video_files_size_in_mb` (200); a value given is written
    into the dataset's `info.json`. A commit writes new files, joined into those sizes later,
    and never changes a file a committed episode is in.

    Episodes are written when they end, `keep="success"` keeping only those whose last
    `success` / `is_success` info is true; an episode a `reset()` cuts short is not written.
    Ended episodes reach the disk within `commit_every` seconds (or four times as long as the
    last commit took, if longer), so a crash loses at most the episodes in flight and those,
    and never leaves a dataset that does not load.

    Stepping is not blocked by the disk or the encoder: steps go through a queue of at most
    `queue_bytes` (512 MiB by default; counting the step being written) to a writer thread.
    If it is full, `when_full="wait"` makes the step wait and `"drop"` drops the step, and
    with it the episodes in flight (each env records again from its next episode); either way
    a `QueueFullWarning` says so, and `stats` counts it.

    `max_episodes` stops keeping episodes once that many are kept (later ones are counted in
    `stats["episodes_beyond"]`). Frames are encoded on `encode_threads` threads (default: up to
    4, one per core), the envs shared among them; each encoder runs on its caller's thread, so
    these are all the threads encoding takes.

    Videos are encoded with `codec` (x264 by default), `crf` (18 for x264, 30 for AV1) and
    `gop` (a keyframe every 2 frames); appending to a dataset encodes with its own parameters
    (leave these out), and asking for others is a `DatasetLayoutError`.

    The dataset folder is opened (checked and locked) at the first `reset()`; a folder that
    holds a dataset of another layout raises `DatasetLayoutError` naming the differences.
    """

    def __init__(
        self,
        env: VectorEnv,
        root: str,
        *,
        task: str | None = None,
        fps: int | None = None,
        keep: str = "all",
        video: bool = True,
        codec: str | None = None,
        crf: int | None = None,
        gop: int | None = None,
        queue_bytes: int = DEFAULT_QUEUE_BYTES,
        when_full: str = "wait",
        commit_every: float = 1.0,
        max_episodes: int | None = None,
        encode_threads: int | None = None,
        robot_type: str | None = None,
        data_files_size_in_mb: float | None = None,
        video_files_size_in_mb: float | None = None,
    ) -> None:
        super().__init__(env)
        require()
        if keep not in ("all", "success"):
            raise ValueError(f"unknown `keep={keep!r}`\nhint: use `keep=\"all\"` or `keep=\"success\"`")
        if when_full not in ("wait", "drop"):
            raise ValueError(f"unknown `when_full={when_full!r}`\nhint: use `when_full=\"wait\"` or `\"drop\"`")
        if queue_bytes < 1:
            raise ValueError(f"`queue_bytes={queue_bytes}` must be at least 1 (a byte budget; default 512 MiB)")
        if encode_threads is not None and encode_threads < 1:
            raise ValueError(f"`encode_threads={encode_threads}` must be at least 1")
        for name, size in (("data_files_size_in_mb", data_files_size_in_mb),
                           ("video_files_size_in_mb", video_files_size_in_mb)):
            if size is not None and not size > 0:
                raise ValueError(f"`{name}={size}` must be a positive number of MB (LeRobot's default: "
                                 f"{100 if name.startswith('data') else 200})")
        if codec is not None:
            check_codec(codec)
        self.root = str(root)
        self.keep, self.when_full = keep, when_full
        self._mode = _mode(env)
        self.fps = self._fps(env, fps)
        self.task = task if task is not None else _task_of(env)
        self._obs_columns = observation_columns(env.single_observation_space)
        self._action = action_column(env.single_action_space)
        self._render = bool(video) and getattr(env, "render_mode", None) == "rgb_array"
        for name, value, least in (("crf", crf, 0), ("gop", gop, 1)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < least):
                raise ValueError(f"`{name}={value!r}` must be a whole number of at least {least}")
        self._codec, self._crf, self._gop = codec, crf, gop
        self._queue_bytes, self._commit_every, self._robot_type = int(queue_bytes), float(commit_every), robot_type
        self._sizes = (data_files_size_in_mb, video_files_size_in_mb)
        self._max_episodes = max_episodes
        self._encode_threads = encode_threads or min(4, usable_cores())
        self.stats: dict[str, Any] = {
            "episodes_kept": 0,  # ended and kept (committed or about to be)
            "episodes_written": 0,  # committed
            "episodes_filtered": 0,
            "episodes_dropped": 0,
            "episodes_cut": 0,
            "episodes_beyond": 0,
            "frames_kept": 0,
            "steps_dropped": 0,
            "steps_waited": 0,
            "seconds_waited": 0.0,
            "queue_bytes_peak": 0,  # the most bytes the queue held (with the step being written)
        }
        self._writer: Writer | None = None
        self._dataset: Dataset | None = None
        self._prev: tuple[dict[str, np.ndarray], list[np.ndarray] | None] | None = None
        self._fresh = np.ones(self.num_envs, dtype=bool)  # envs whose next step is not recorded
        self._failed = np.zeros(self.num_envs, dtype=bool)  # envs that failed, until reset
        self._gap = False
        self._warned = False
        self._closed = False
        # Stops the writer (committing what ended) on `close()`, when the wrapper is collected,
        # or at interpreter exit; holds no reference to the wrapper.
        self._finalizer: weakref.finalize | None = None

    @staticmethod
    def _fps(env: VectorEnv, fps: int | None) -> int:
        return frame_rate(env.metadata.get("render_fps"), fps)

    # Opening the dataset at the first reset ------------------------------------------------

    def _open(self, frames: list[np.ndarray] | None) -> None:
        codec = self._codec or DEFAULT_CODEC
        render: dict[str, tuple[int, ...]] = {}
        if self._render:
            if frames is None or any(f is None for f in frames):
                raise RecordingError(
                    "the env was made with `render_mode=\"rgb_array\"` but `render()` gave no frame\n"
                    "hint: pass `video=False` to record without frames"
                )
            render[RENDER_KEY] = tuple(np.asarray(frames[0]).shape)
        columns = [*self._obs_columns, self._action, *STEP_COLUMNS]
        wanted = features(columns, self.fps, CANONICAL[codec], render)
        dataset = Dataset(self.root, self.fps, wanted, self._robot_type, *self._sizes,
                          codec=self._codec, crf=self._crf, gop=self._gop)
        self._dataset = dataset
        numeric = [c.name for c in self._obs_columns if not c.video]
        videos = [c.name for c in self._obs_columns if c.video]
        try:
            self._writer = Writer(
                dataset, self.num_envs, numeric, videos, RENDER_KEY if self._render else None, self.fps,
                self.keep, self._commit_every, self._queue_bytes, self.stats, self._max_episodes,
                self._encode_threads,
            )
        except BaseException:
            dataset.close()
            raise
        self._finalizer = weakref.finalize(self, _stop_writer, self._writer, dataset)

    # The step path ------------------------------------------------------------------------

    def _observe(self, obs: Any) -> dict[str, np.ndarray]:
        return {c.name: np.array(c.batch(obs, self.num_envs), copy=True) for c in self._obs_columns}

    def _frames(self) -> list[np.ndarray] | None:
        if not self._render:
            return None
        frames = self.env.render()
        return None if frames is None else list(frames)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self._check()
        # Read before the env is called: Gymnasium's vector envs pop `reset_mask` from the
        # caller's options.
        mask = (options or {}).get("reset_mask")
        mask = None if mask is None else np.array(mask, dtype=bool, copy=True).reshape(self.num_envs)
        obs, info = self.env.reset(seed=seed, options=options)
        frames = self._frames()
        if self._writer is None:
            self._open(frames)
        self._put(Reset(mask))
        self._prev = (self._observe(obs), frames)
        if mask is None:
            self._fresh[:] = False
            self._failed[:] = False
        else:
            self._fresh[mask] = False
            self._failed[mask] = False
        return obs, info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        self._check()
        if self._prev is None:
            raise RecordingError("`step` before `reset`\nhint: call `reset()` first, as Gymnasium requires")
        failed = None
        try:
            obs, rewards, terminated, truncated, info = self.env.step(actions)
        except Exception as e:
            partial = self._failed_envs(e)
            if partial is None:
                # Which envs stepped is unknown (Gymnasium's vector envs raise with no
                # results): every episode in flight is dropped.
                self._gap = True
                raise
            error = e
            failed, (obs, rewards, terminated, truncated, info) = partial
        terminated_ = np.array(terminated, dtype=bool, copy=True)
        truncated_ = np.array(truncated, dtype=bool, copy=True)
        if failed is not None:  # the failed envs' rows are not meaningful
            terminated_[failed] = truncated_[failed] = False
            self._failed |= failed
        done = terminated_ | truncated_
        valid = ~self._fresh & ~self._failed
        success = None
        if done.any():
            same_step = self._mode == AutoresetMode.SAME_STEP
            success = [_success(info, i, same_step) if done[i] else None for i in range(self.num_envs)]
            if self.keep == "success" and failed is None:  # (a failed step's info is lost)
                unknown = [i for i in np.flatnonzero(done & valid) if success[i] is None]
                if unknown:
                    raise RecordingError(
                        f"env {unknown[0]} ended an episode without a `success` or `is_success` info, "
                        "so `keep=\"success\"` cannot tell whether to keep it\n"
                        "hint: record with `keep=\"all\"`, or wrap the env so its info says `success`"
                    )
        prev_obs, prev_frames = self._prev
        self._put(
            Step(
                obs=prev_obs,
                frames=prev_frames,
                action=np.array(self._action.batch(actions, self.num_envs), copy=True),
                reward=np.array(rewards, dtype=np.float64, copy=True),
                terminated=terminated_,
                truncated=truncated_,
                valid=valid,
                success=success,
                task=self.task,
                failed=failed,
            )
        )
        if self._mode == AutoresetMode.NEXT_STEP:
            self._fresh = done
        elif self._mode == AutoresetMode.DISABLED:
            self._fresh = self._fresh | done
        if failed is not None:
            # The failed envs must be reset; the others go on from these results.
            try:
                frames = self._frames()
            except Exception:  # no frames to go on with: the episodes in flight are dropped
                frames, self._gap = None, True
            self._prev = (self._observe(obs), frames)
            raise error
        self._prev = (self._observe(obs), self._frames())
        return obs, rewards, terminated, truncated, info

    def _failed_envs(self, e: Exception) -> tuple[np.ndarray, tuple] | None:
        """The envs that failed in a step that raised and the others' results, where the env
        says which (envhub's `EnvFailedError`: `env_ids`, and `results`: Gymnasium's five, or
        the session's raw ones, decoded here); else `None`."""
        ids, results = getattr(e, "env_ids", None), getattr(e, "results", None)
        if ids is None or not isinstance(results, tuple):
            return None
        if len(results) != 5:
            codec = getattr(self.env.unwrapped, "_codec", None)  # envhub's VectorEnv
            if codec is None or len(results) < 4:
                return None
            results = (codec.obs(results[0]), results[1], results[2], results[3], {})
        mask = np.zeros(self.num_envs, dtype=bool)
        mask[np.asarray(list(ids), dtype=np.int64)] = True
        return mask, results

    def _put(self, item: Step | Reset) -> None:
        assert self._writer is not None
        q = self._writer.queue
        item.gap = self._gap
        nbytes = _nbytes(item)
        if q.put(item, nbytes, timeout=0):
            self._gap = False
            return
        if self.when_full == "drop" and isinstance(item, Step):
            self.stats["steps_dropped"] += 1
            self._gap = True
            self._warn(
                f"the recorder's queue ({_mib(self._queue_bytes)}) is full: a step is dropped, and "
                "with it the episodes in flight (each env records again from its next episode)"
            )
            return
        self.stats["steps_waited"] += 1
        self._warn(f"the recorder's queue ({_mib(self._queue_bytes)}) is full: steps wait for the writer")
        start = time.monotonic()
        while not q.put(item, nbytes, timeout=0.5):
            self._check()
        self.stats["seconds_waited"] += time.monotonic() - start
        self._gap = False

    def _warn(self, message: str) -> None:
        if not self._warned:
            self._warned = True
            warnings.warn(
                f"{message}\nhint: a larger `queue_bytes`, fewer envs or cameras, or `video=False`; "
                "`stats` counts every wait and drop",
                QueueFullWarning,
                stacklevel=4,
            )

    def _check(self) -> None:
        if self._writer is not None and self._writer.error is not None:
            err = self._writer.error
            raise RecordingError(f"the recording writer failed: {type(err).__name__}: {err}") from err
        if self._writer is not None and not self._writer.thread.is_alive() and not self._closed:
            raise RecordingError("the recording writer stopped\nhint: this is a bug; the dataset keeps what it committed")

    def send(self, *args: Any, **kwargs: Any) -> None:
        raise RecordingError(
            "`RecordEpisodes` records lock-step `step()` calls; `send`/`recv` would bypass it\n"
            "hint: step the wrapper with `step()`"
        )

    recv = send

    def close(self, **kwargs: Any) -> None:
        """Commits the ended episodes, stops the writer, then closes the env."""
        if not self._closed:
            self._closed = True
            try:
                if self._finalizer is not None:
                    self._finalizer()
            finally:
                if self._writer is not None:
                    self.stats["queue_bytes_peak"] = self._writer.queue.peak
                if self.stats["steps_dropped"] or self.stats["steps_waited"]:
                    s = self.stats
                    warnings.warn(
                        f"recording into `{self.root}`: the writer's queue was full; {s['steps_waited']} "
                        f"steps waited ({s['seconds_waited']:.1f} s), {s['steps_dropped']} steps dropped "
                        f"({s['episodes_dropped']} episodes dropped)",
                        QueueFullWarning,
                        stacklevel=2,
                    )
            err = self._writer.error if self._writer is not None else None
            self.env.close(**kwargs)
            if err is not None:
                raise RecordingError(f"the recording writer failed: {type(err).__name__}: {err}") from err
        else:
            self.env.close(**kwargs)


def _stop_writer(writer: Writer, dataset: Dataset) -> None:
    """Lets the writer commit what ended and stop, then releases the dataset."""
    try:
        if writer.thread.is_alive():
            while writer.thread.is_alive() and not writer.queue.put(STOP, 0, timeout=0.5):
                pass
            writer.thread.join()
    finally:
        dataset.close()


def _nbytes(item: Step | Reset) -> int:
    """The bytes a queued item holds (its arrays)."""
    if isinstance(item, Reset):
        return 0 if item.mask is None else item.mask.nbytes
    total = sum(a.nbytes for a in item.obs.values()) + item.action.nbytes + 3 * item.reward.nbytes
    if item.frames is not None:
        total += sum(np.asarray(f).nbytes for f in item.frames if f is not None)
    return int(total)


def _mib(n: int) -> str:
    return f"{n / 2**20:.4g} MiB"


def _task_of(env: VectorEnv) -> str:
    """The catalog entry's description for an envhub env (its `registry_id`), else the id of
    the env's spec, else its class name."""
    registry_id = getattr(env.unwrapped, "registry_id", None)
    if isinstance(registry_id, str):
        try:
            from ..client.registry import EnvRegistry

            entry = EnvRegistry().get(registry_id)
            return entry.description or entry.name or registry_id
        except Exception:  # not a catalog id (the drop-in's env factories): fall through
            pass
    spec = getattr(env, "spec", None) or getattr(env.unwrapped, "spec", None)
    if spec is None:
        try:  # a vector env of Gymnasium envs (Sync/AsyncVectorEnv, the drop-in): env 0's
            spec = env.get_attr("spec")[0]
        except Exception:
            spec = None
    if spec is not None and getattr(spec, "id", None):
        return str(spec.id)
    return type(env.unwrapped).__name__
