"""`record` (episodes of a catalog entry into a dataset) and `record_video` (a quick MP4)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ._wrapper import RecordEpisodes, _success

Policy = Callable[[Any], Any]


def task_of(id: str) -> str:
    """The catalog entry's description (the dataset's task text), else the id."""
    from ..registry import EnvRegistry

    try:
        return EnvRegistry().get(id).description or id
    except Exception:  # an id the catalog does not describe still records
        return id


def load_policy(spec: str) -> Policy:
    """`module:function` to the callable; it takes the batched observation and returns actions
    (or takes `(obs, action_space)` when it has two parameters)."""
    module, sep, name = spec.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"policy `{spec}` is not `module:function`\nhint: e.g. `mypkg.policies:act`")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"cannot load policy `{spec}`: {exc}\nhint: is the module importable?") from exc
    return fn


def _act(policy: Policy | None, obs, space):
    if policy is None:
        return space.sample()
    try:
        return policy(obs, space)
    except TypeError:
        return policy(obs)


def record(
    id: str,
    episodes: int,
    root: str | Path,
    policy: Policy | None = None,
    num_envs: int = 1,
    *,
    repo_id: str | None = None,
    filter: str = "all",
    video: bool = True,
    seed: int | None = 0,
    max_steps: int | None = None,
    progress: Callable[[int], None] | None = None,
    env: Any = None,
    **make_kwargs: Any,
) -> dict:
    """Steps `num_envs` envs of catalog entry `id` (or the given vector `env`) with `policy`
    (random actions by default) until `episodes` episodes are written to the LeRobot dataset
    at `root`. Returns the recorder's counts. `max_steps` bounds the vector steps."""
    if episodes < 1:
        raise ValueError(f"`episodes` is {episodes}\nhint: record at least 1 episode")
    if env is None:
        from .._factory import make_vec

        env = make_vec(id, num_envs, render_mode="rgb_array" if video else None, **make_kwargs)
    rec = RecordEpisodes(
        env, str(root), repo_id=repo_id or f"envhub/{id}", task=task_of(id), filter=filter, video=video
    )
    try:
        obs, _ = rec.reset(seed=seed)
        space = rec.action_space
        if seed is not None:
            space.seed(seed)
        steps = 0
        kept = 0
        while kept < episodes:
            obs, _, terms, truncs, info = rec.step(_act(policy, obs, space))
            steps += 1
            ended = np.flatnonzero(np.logical_or(terms, truncs))
            if filter == "success":
                ended = [i for i in ended if _success(info, i)]
            if len(ended):
                kept += len(ended)
                if progress is not None:
                    progress(min(len(ended), episodes - kept + len(ended)))
            if max_steps is not None and steps >= max_steps:
                break
    finally:
        rec.close()
    # Episodes beyond `episodes` that ended on the same step are kept (they are whole).
    return dict(rec.stats)


def record_video(
    id: str,
    out: str | Path,
    steps: int = 300,
    policy: Policy | None = None,
    fps: int | None = None,
    codec: str = "libx264",
    seed: int | None = 0,
    **make_kwargs: Any,
) -> int:
    """The first env's `render()` frames over `steps` steps of catalog entry `id`, as an MP4.
    Returns the number of frames written."""
    from .._factory import make_vec
    from ._layout import _encode

    env = make_vec(id, 1, render_mode="rgb_array", **make_kwargs)
    try:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        frames = [np.array(env.render()[0], copy=True)]
        for _ in range(steps):
            obs, *_ = env.step(_act(policy, obs, env.action_space))
            frames.append(np.array(env.render()[0], copy=True))
        rate = fps or int(round(float(env.metadata.get("render_fps") or 30)))
    finally:
        env.close()
    _encode(Path(out), frames, rate, codec, "yuv420p", 18)
    return len(frames)
