"""`record` (episodes of a catalog entry into a dataset), `record_video` (one env's frames into
an MP4) and the policies they step with."""

from __future__ import annotations

import importlib
import inspect
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..wire.errors import EnvHubError
from ._encoding import DEFAULT_CODEC, requested
from ._video import EpisodeVideo, check_codec, pix_fmt
from ._wrapper import RecordEpisodes
from .errors import require

Policy = Callable[..., Any]


def load_policy(spec: str) -> Policy:
    """`module:function` to the callable (the module imported from `sys.path`, which holds
    the current directory when run as `python -m`)."""
    module, sep, name = spec.partition(":")
    if not sep or not module or not name:
        raise ValueError(f"the policy `{spec}` is not `module:function`\nhint: e.g. `--policy my_policies:act`")
    try:
        obj: Any = importlib.import_module(module)
    except ImportError as e:
        raise ValueError(f"cannot import the policy's module `{module}`: {e}\nhint: is it on PYTHONPATH?") from e
    for part in name.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"the module `{module}` has no `{name}`\nhint: name a function of it, `{module}:NAME`")
        obj = getattr(obj, part)
    if not callable(obj):
        raise ValueError(f"the policy `{spec}` is not callable")
    return obj


def _actor(policy: Policy | None, action_space: Any) -> Callable[[Any], Any]:
    """`policy(obs)`, or `policy(obs, action_space)` for a policy that takes two arguments;
    random actions from `action_space` without one."""
    if policy is None:
        return lambda obs: action_space.sample()
    try:
        params = [
            p for p in inspect.signature(policy).parameters.values()
            if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty
        ]
    except (TypeError, ValueError):  # builtins without a signature
        params = []
    if len(params) >= 2:
        return lambda obs: policy(obs, action_space)
    return policy


def record(
    id: str,
    episodes: int,
    root: str | os.PathLike,
    *,
    num_envs: int = 1,
    policy: Policy | None = None,
    keep: str = "all",
    video: bool = True,
    seed: int | None = 0,
    max_steps: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    recorder: dict[str, Any] | None = None,
    **make_kwargs: Any,
) -> dict[str, Any]:
    """Steps `num_envs` envs of catalog entry `id` with `policy` (random actions by default)
    until `episodes` episodes are kept in the LeRobot dataset at `root`, and returns the
    recorder's `stats`. `policy(obs)` (or `policy(obs, action_space)`) returns a batch of
    actions. `max_steps` bounds the batched steps (for `keep="success"` with a policy that
    rarely succeeds); `progress(kept, episodes)` is called as episodes are kept; `recorder`
    holds more `RecordEpisodes` options; `make_kwargs` go to `envhub.make_vec`."""
    from ..client.factory import make_vec

    require()
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"`episodes={episodes!r}`\nhint: record at least 1 episode")
    env = None
    if video:
        try:
            env = make_vec(id, num_envs, render_mode="rgb_array", **make_kwargs)
        except EnvHubError as e:
            # Envs that draw no frames (robosuite's cameras render into the observation) are
            # recorded without the render video; said, since `video=True` asked for one.
            env = make_vec(id, num_envs, **make_kwargs)
            reason = str(e).strip().splitlines()[-2:]
            warnings.warn(
                f"recording `{id}` without a `render()` video: it does not render `rgb_array` frames "
                f"({' '.join(reason)})\nhint: `video=False` (`--no-video`) says so and skips this attempt",
                stacklevel=2,
            )
    if env is None:
        env = make_vec(id, num_envs, **make_kwargs)
    try:
        rec = RecordEpisodes(env, str(root), keep=keep, video=video, max_episodes=episodes, **(recorder or {}))
    except BaseException:
        env.close()
        raise
    try:
        obs, _ = rec.reset(seed=seed)
        if seed is not None:
            rec.action_space.seed(seed)
        act = _actor(policy, rec.action_space)
        steps, shown = 0, -1
        while rec.stats["episodes_kept"] < episodes:
            if max_steps is not None and steps >= max_steps:
                break
            obs, *_ = rec.step(act(obs))
            steps += 1
            if progress is not None and rec.stats["episodes_kept"] != shown:
                shown = rec.stats["episodes_kept"]
                progress(min(shown, episodes), episodes)
    finally:
        rec.close()
    if progress is not None:
        progress(min(rec.stats["episodes_written"], episodes), episodes)
    return dict(rec.stats, steps=steps)


def record_video(
    id: str,
    out: str | os.PathLike,
    *,
    steps: int = 300,
    policy: Policy | None = None,
    seed: int | None = 0,
    fps: int | None = None,
    codec: str = DEFAULT_CODEC,
    crf: int | None = None,
    **make_kwargs: Any,
) -> int:
    """`render()` frames of one env of catalog entry `id` over `steps` steps (episodes
    following each other), as an MP4 at `out`; returns the number of frames."""
    from ..client.factory import make_vec

    require()
    check_codec(codec)
    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise ValueError(f"the video `{out}` must be an `.mp4` file\nhint: e.g. `--video out.mp4`")
    env = make_vec(id, 1, render_mode="rgb_array", **make_kwargs)
    tmp = out.with_name(f".{out.name}.tmp.mp4")
    video = None
    try:
        rate = RecordEpisodes._fps(env, fps)
        obs, _ = env.reset(seed=seed)
        if seed is not None:
            env.action_space.seed(seed)
        act = _actor(policy, env.action_space)
        for k in range(steps + 1):
            frame = np.asarray(env.render()[0])
            if video is None:
                out.parent.mkdir(parents=True, exist_ok=True)
                h, w = frame.shape[:2]
                video = EpisodeVideo(tmp, rate, requested(codec, crf, rate, pix_fmt(w, h), w, h))
            video.add(frame)
            if k < steps:
                obs, *_ = env.step(act(obs))
        video.finish()
        os.replace(tmp, out)
        return video.frames
    except BaseException:
        if video is not None:
            video.abandon()
        raise
    finally:
        env.close()
