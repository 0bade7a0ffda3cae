"""`RecordEpisodes`: a VectorEnv wrapper that keeps every ended episode in a LeRobot dataset.

The step path copies the batch once (slot views are overwritten by the next step) and hands it
to a writer thread through a bounded queue; the thread splits the batch per env, keeps each
env's episode in memory, and encodes and writes it when it ends.
"""

from __future__ import annotations

import queue
import threading
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from ._layout import DatasetWriter, video_feature

RENDER_KEY = "observation.images.render"
_STOP = object()


def _is_image(space: spaces.Space) -> bool:
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and space.shape[2] == 3
    )


def _numeric(space: spaces.Space, where: str) -> dict:
    if isinstance(space, spaces.Box):
        n = int(np.prod(space.shape))
        return {"dtype": str(space.dtype), "shape": [n], "names": None}
    if isinstance(space, spaces.Discrete):
        return {"dtype": "int64", "shape": [1], "names": None}
    if isinstance(space, spaces.MultiDiscrete | spaces.MultiBinary):
        n = int(np.prod(space.shape))
        return {"dtype": str(space.dtype), "shape": [n], "names": None}
    raise TypeError(
        f"the {where} space `{space}` cannot be recorded\n"
        "hint: recording takes Box, Discrete, MultiDiscrete, MultiBinary and Dict of those"
    )


def _success(info: dict, i: int) -> bool:
    for key in ("success", "is_success"):
        if key in info:
            mask = info.get(f"_{key}")
            if mask is not None and not mask[i]:
                continue
            return bool(np.asarray(info[key])[i])
    return False


class RecordEpisodes(VectorWrapper):
    """Records every env's ended episodes of `env` into the LeRobot v3 dataset at `root`.

    Frame `t` holds the observation before step `t`, its action, and the reward and done
    flags the step returned (`next.*`). Box observations are `observation.state`; a Dict
    observation's uint8 HxWx3 entries become videos `observation.images.<key>`, its other
    entries `observation.<key>`; with `video=True` and `render_mode="rgb_array"`, `render()`
    frames become `observation.images.render`. `filter="success"` keeps only episodes whose
    last `info["success"]`/`info["is_success"]` is true. When the writer's queue is full,
    `when_full="wait"` blocks the step and `"drop"` drops the envs' episodes in flight; both
    are counted and warned about (see `stats`)."""

    def __init__(
        self,
        env: VectorEnv,
        root: str,
        repo_id: str = "envhub/recording",
        fps: int | None = None,
        task: str | None = None,
        filter: str = "all",
        video: bool = True,
        codec: str = "libx264",
        queue_size: int = 256,
        when_full: str = "wait",
        robot_type: str | None = None,
    ) -> None:
        super().__init__(env)
        if filter not in ("all", "success"):
            raise ValueError(f"unknown filter `{filter}`\nhint: use `all` or `success`")
        if when_full not in ("wait", "drop"):
            raise ValueError(f"unknown `when_full` `{when_full}`\nhint: use `wait` or `drop`")
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if str(getattr(mode, "value", mode)) not in ("NextStep", "next_step", "SameStep", "same_step"):
            raise ValueError(
                f"recording needs the `next_step` or `same_step` autoreset mode, not `{mode}`"
                "\nhint: make the vector env with autoreset_mode=\"next_step\""
            )
        self._same_step = "same" in str(getattr(mode, "value", mode)).lower()
        if fps is None:
            fps = env.metadata.get("render_fps")
        if not fps:
            raise ValueError(
                "the env names no `render_fps` in its metadata\nhint: pass `fps=`"
            )
        self.fps = int(round(float(fps)))
        self.filter, self.when_full = filter, when_full
        spec = getattr(env, "spec", None)
        self.task = task or (spec.id if spec is not None else "") or "rollout"
        obs_space = env.single_observation_space
        feats: dict[str, dict] = {}
        self._obs_keys: list[tuple[str | None, str, bool]] = []  # (dict key, feature, image)
        if isinstance(obs_space, spaces.Dict):
            for k, sub in obs_space.spaces.items():
                if _is_image(sub):
                    name = f"observation.images.{k}"
                    feats[name] = video_feature(sub.shape, self.fps, codec, "yuv420p")
                    self._obs_keys.append((k, name, True))
                else:
                    name = "observation.state" if k == "state" else f"observation.{k}"
                    feats[name] = _numeric(sub, f"observation `{k}`")
                    self._obs_keys.append((k, name, False))
        elif _is_image(obs_space):
            feats["observation.image"] = video_feature(obs_space.shape, self.fps, codec, "yuv420p")
            self._obs_keys.append((None, "observation.image", True))
        else:
            feats["observation.state"] = _numeric(obs_space, "observation")
            self._obs_keys.append((None, "observation.state", False))
        feats["action"] = _numeric(env.single_action_space, "action")
        feats["next.reward"] = {"dtype": "float32", "shape": [1], "names": None}
        feats["next.done"] = {"dtype": "bool", "shape": [1], "names": None}
        feats["next.terminated"] = {"dtype": "bool", "shape": [1], "names": None}
        feats["next.truncated"] = {"dtype": "bool", "shape": [1], "names": None}
        self._render = bool(video) and getattr(env, "render_mode", None) == "rgb_array"
        # The frames' shape is known at the first reset (envs render only after one), so
        # the dataset opens there when frames are recorded.
        self._open = lambda extra: DatasetWriter(
            root, repo_id, self.fps, {**feats, **extra}, robot_type=robot_type, codec=codec
        )
        self._codec = codec
        self._writer = None if self._render else self._open({})
        self.root = Path(root)
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self.stats = {
            "episodes_written": 0,
            "episodes_filtered": 0,
            "episodes_dropped": 0,
            "steps_dropped": 0,
            "waits": 0,
        }
        self._error: BaseException | None = None
        self._last: tuple | None = None  # (obs copy, render copy) before the next step
        self._fresh = np.ones(self.num_envs, dtype=bool)  # next step only resets (next_step)
        self._thread = threading.Thread(target=self._run, name="envhub-record", daemon=True)
        self._buffers: list[list] = [[] for _ in range(self.num_envs)]
        self._poisoned = np.zeros(self.num_envs, dtype=bool)
        self._closed = False
        self._thread.start()

    # -- the step path -------------------------------------------------------------------

    def _frames(self) -> np.ndarray | None:
        if not self._render:
            return None
        return np.array(self.env.render(), copy=True)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        frames = self._frames()
        if self._writer is None:
            shape = frames.shape[1:]
            self._writer = self._open({RENDER_KEY: video_feature(shape, self.fps, self._codec, "yuv420p")})
        self._put(("reset",))
        self._last = (_copy(obs), frames)
        self._fresh[:] = False
        return obs, info

    def step(self, actions):
        self._check()
        obs, rewards, terms, truncs, info = self.env.step(actions)
        done = np.logical_or(terms, truncs)
        success = np.array([_success(info, i) for i in range(self.num_envs)]) if done.any() else None
        valid = ~self._fresh
        prev_obs, prev_frames = self._last
        item = (
            "step",
            prev_obs,
            prev_frames,
            np.array(actions, copy=True),
            np.asarray(rewards, dtype=np.float32).copy(),
            np.asarray(terms, dtype=bool).copy(),
            np.asarray(truncs, dtype=bool).copy(),
            valid.copy(),
            success,
        )
        self._put(item)
        self._last = (_copy(obs), self._frames())
        if self._same_step:
            self._fresh[:] = False
        else:
            self._fresh = done.copy()
        return obs, rewards, terms, truncs, info

    def _put(self, item) -> None:
        try:
            self._queue.put_nowait(item)
            return
        except queue.Full:
            pass
        if self.when_full == "wait":
            self.stats["waits"] += 1
            self._queue.put(item)
        elif item[0] == "step":
            # The step is lost, so every env's episode in flight is incomplete: drop them.
            self.stats["steps_dropped"] += 1
            self._queue.put(("poison",))  # blocks only until the thread takes one item
        else:
            self._queue.put(item)

    def _check(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            raise RuntimeError(f"the recording writer failed: {err}") from err

    def close(self, **kwargs: Any) -> None:
        if not self._closed:
            self._closed = True
            self._queue.put(_STOP)
            self._thread.join()
            s = self.stats
            if s["steps_dropped"] or s["waits"]:
                warnings.warn(
                    f"recording into `{self.root}`: the writer queue was full; "
                    f"{s['waits']} steps waited, {s['steps_dropped']} steps dropped "
                    f"({s['episodes_dropped']} episodes dropped)\nhint: a larger `queue_size`, "
                    "fewer envs, or `video=False` keeps up",
                    stacklevel=2,
                )
        self._check()
        self.env.close(**kwargs)

    # -- the writer thread ---------------------------------------------------------------

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            try:
                self._handle(item)
            except BaseException as exc:  # reported on the next step or close
                self._error = exc

    def _handle(self, item) -> None:
        kind = item[0]
        if kind == "reset":
            self._abandon(all_envs=True)
            return
        if kind == "poison":
            self._abandon(all_envs=False)
            return
        _, obs, frames, actions, rewards, terms, truncs, valid, success = item
        for i in np.flatnonzero(valid):
            self._buffers[i].append(
                (_row(obs, i), None if frames is None else frames[i], actions[i], rewards[i], terms[i], truncs[i])
            )
            if terms[i] or truncs[i]:
                self._end(i, bool(success[i]) if success is not None else False)

    def _abandon(self, all_envs: bool) -> None:
        for i in range(self.num_envs):
            if self._buffers[i] and not all_envs:
                self.stats["episodes_dropped"] += 1
                self._poisoned[i] = True
            self._buffers[i] = []

    def _end(self, i: int, success: bool) -> None:
        rows, self._buffers[i] = self._buffers[i], []
        if self._poisoned[i]:
            self._poisoned[i] = False
            return
        if self.filter == "success" and not success:
            self.stats["episodes_filtered"] += 1
            return
        columns: dict[str, np.ndarray] = {}
        videos: dict[str, list] = {}
        for key, name, image in self._obs_keys:
            vals = [r[0] if key is None else r[0][key] for r in rows]
            if image:
                videos[name] = vals
            else:
                columns[name] = np.stack([np.asarray(v).reshape(-1) for v in vals])
        if self._render:
            videos[RENDER_KEY] = [r[1] for r in rows]
        columns["action"] = _squeeze(np.stack([np.asarray(r[2]).reshape(-1) for r in rows]))
        columns["next.reward"] = np.array([r[3] for r in rows], dtype=np.float32)
        columns["next.terminated"] = np.array([r[4] for r in rows], dtype=bool)
        columns["next.truncated"] = np.array([r[5] for r in rows], dtype=bool)
        columns["next.done"] = columns["next.terminated"] | columns["next.truncated"]
        for name in list(columns):
            columns[name] = _squeeze(columns[name])
        self._writer.write_episode(columns, videos, self.task)
        self.stats["episodes_written"] += 1


def _squeeze(a: np.ndarray) -> np.ndarray:
    return a[:, 0] if a.ndim == 2 and a.shape[1] == 1 else a


def _copy(obs):
    if isinstance(obs, dict):
        return {k: np.array(v, copy=True) for k, v in obs.items()}
    return np.array(obs, copy=True)


def _row(obs, i):
    if isinstance(obs, dict):
        return {k: v[i] for k, v in obs.items()}
    return obs[i]
