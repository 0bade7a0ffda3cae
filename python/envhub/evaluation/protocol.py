"""What a benchmark's protocol does to each observation and action: the keys the policy is
shown, images flipped `[::-1, ::-1]` (robosuite renders upside down) and resized with
padding as vla-eval does (PIL bilinear, aspect kept, black bars), and the checks an action
passes before it reaches the env."""

from __future__ import annotations

from typing import Any

import numpy as np

from .images import resize_with_pad

__all__ = ["ActionError", "Observer", "check_actions", "resize_with_pad"]


class ActionError(ValueError):
    """A policy answer that is not an action (or chunk) of the env's action space."""


class Observer:
    """The protocol's view of one env's observation (`observation:` of the benchmark)."""

    def __init__(self, spec: dict[str, Any], space: Any) -> None:
        self.keys: list[str] | None = spec.get("keys")
        self.flip = set(spec.get("flip") or [])
        self.resize: list[int] | None = spec.get("resize")
        self.video: str | None = spec.get("video")
        spaces = getattr(space, "spaces", None)
        names = list(spaces) if isinstance(spaces, dict) else []
        for key in list(self.keys or []) + sorted(self.flip) + ([self.video] if self.video else []):
            if not names:
                raise ValueError(f"the benchmark names observation key `{key}` but the env's observation is not a dict")
            if key not in names:
                from .benchmarks import closest

                raise closest(key, names, "observation key")
        if self.video is None:
            # The first image of the observation (after key selection) is the episode's video.
            candidates = self.keys or names
            self.video = next((k for k in candidates if _is_image(spaces[k])), None) if names else None
        self.identity = not self.keys and not self.flip and not self.resize

    def __call__(self, obs: Any) -> Any:
        """The observation as the policy sees it (the env's own where the protocol changes
        nothing: a view, no copy)."""
        if self.identity or not isinstance(obs, dict):
            return obs
        keys = self.keys or list(obs)
        return {k: self._image(k, obs[k]) for k in keys}

    def _image(self, key: str, value: Any) -> Any:
        if key in self.flip:
            value = np.ascontiguousarray(value[::-1, ::-1])
        if self.resize and getattr(value, "ndim", 0) == 3 and value.dtype == np.uint8:
            value = resize_with_pad(value, *self.resize)
        return value

    def frame(self, obs: Any) -> np.ndarray | None:
        """The episode video's frame of this observation (upright where the protocol flips)."""
        if self.video is None or not isinstance(obs, dict):
            return None
        value = obs[self.video]
        if self.video in self.flip:
            return np.ascontiguousarray(value[::-1, ::-1])
        return np.array(value)


def _is_image(space: Any) -> bool:
    shape = getattr(space, "shape", None) or ()
    return len(shape) == 3 and shape[-1] == 3 and getattr(space, "dtype", None) == np.uint8


def check_actions(answer: Any, space: Any, sign: list[int] | None = None) -> np.ndarray:
    """`answer` as a chunk `(k, *action_shape)` in the space's dtype: one action or several;
    anything else (another shape, a dtype that is not a number, NaN or infinity) raises
    `ActionError` naming the action space."""
    shape = tuple(space.shape)
    try:
        a = np.asarray(answer)
    except Exception as e:
        raise ActionError(f"the policy returned {type(answer).__name__}, not an action of {space}: {e}") from None
    if a.dtype.kind not in "fiu":
        raise ActionError(f"the policy returned an action of dtype {a.dtype}; the action space is {space}")
    if a.shape == shape:
        a = a[None]
    elif not (a.ndim == len(shape) + 1 and a.shape[1:] == shape and a.shape[0] >= 1):
        raise ActionError(
            f"the policy returned an action of shape {a.shape}; the action space is {space} "
            f"(an action {shape} or a chunk (k, {', '.join(map(str, shape))}))"
        )
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ActionError(f"the policy returned a non-finite action {a.tolist()}; the action space is {space}")
    a = a.astype(space.dtype, copy=True)
    if sign:
        a[..., sign] = np.where(a[..., sign] < 0, -1, 1)
    return a
