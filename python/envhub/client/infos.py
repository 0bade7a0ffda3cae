"""Gymnasium's vector info layout (each key an array over the envs plus a `_key` mask of the
envs that reported it) built from the envs' infos in one pass: the fast path of
`envhub.VectorEnv` and `envhub.AsyncVectorEnv`, which otherwise batch value by value as
Gymnasium's `VectorEnv._add_info` does, allocating a fresh mask for every value."""

from __future__ import annotations

from typing import Any

import numpy as np

_SCALARS = (int, float, bool)


def flat_infos(infos: list[dict[str, Any] | None], n: int) -> dict[str, Any] | None:
    """What Gymnasium's `VectorEnv._add_info` makes of these envs' infos (same keys, order,
    dtypes and masks), or None where its recursion or special cases apply (a nested dict, a
    list, a `final_obs` key, a key that starts with `_` and so may collide with a mask):
    that step then takes the value-by-value path."""
    out: dict[str, Any] = {}
    for k, info in enumerate(infos):
        if not info:
            continue
        for key, value in info.items():
            if type(key) is not str or key[:1] == "_" or key == "final_obs" or isinstance(value, dict | list):
                return None
            column = out.get(key)
            if column is None:
                t = type(value)
                if t in _SCALARS or issubclass(t, np.number):
                    column = np.zeros(n, dtype=t)
                elif isinstance(value, np.ndarray):
                    column = np.zeros((n, *value.shape), dtype=value.dtype)
                else:
                    column = np.full(n, fill_value=None, dtype=object)
                out[key] = column
                out[f"_{key}"] = np.zeros(n, dtype=np.bool_)
            column[k] = value
            out[f"_{key}"][k] = True
    return out
