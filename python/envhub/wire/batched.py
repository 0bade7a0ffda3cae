"""One env's part of Gymnasium's batched values and vector infos (used by the worker, which
serves vector envs, and by the SB3 wrapper, which hands SB3 one info per env)."""

from __future__ import annotations

from typing import Any


def env_value(batched: Any, i: int) -> Any:
    """Env `i`'s value of a batched one: an array with a leading env axis (or an object array
    of per-env values, as Gymnasium's `final_obs`), or a dict or tuple of them."""
    if isinstance(batched, dict):
        return {k: env_value(v, i) for k, v in batched.items()}
    if isinstance(batched, tuple):
        return tuple(env_value(v, i) for v in batched)
    return batched[i]


def env_info(batched: dict[str, Any], i: int, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """Env `i`'s info from Gymnasium's batched vector info (`key` and its `_key` mask)."""
    out: dict[str, Any] = {}
    for key, value in batched.items():
        if key in skip or (key.startswith("_") and key[1:] in batched):
            continue
        mask = batched.get(f"_{key}")
        if mask is not None and not mask[i]:
            continue
        out[key] = env_info(value, i) if isinstance(value, dict) else value[i]
    return out
