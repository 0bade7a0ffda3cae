"""Python objects through the data plane's text fields (reset options, infos).

The data plane carries an env's info as JSON of numbers, flags and text, and reset options
as JSON: enough for `make_vec`, lossy for a drop-in replacement of Gymnasium's
`AsyncVectorEnv`, whose infos and options are any picklable object. There the worker and the
client wrap the whole object in one text value, `{KEY: base64(pickle)}`, so it arrives as it
left (types, nesting, numpy dtypes). Both ends are the same user's processes, as with
Gymnasium's own pipes.

Pickling numpy scalars costs more than some MuJoCo envs' step, so an info whose values are
all numbers, flags and text travels as plain JSON instead, with the numpy dtype of each
numpy scalar beside it (`TYPES`), which is exact: Gymnasium batches a value by its type.
"""

from __future__ import annotations

import binascii
import functools
import json
import math
import pickle
from typing import Any

import numpy as np

#: The key of a wrapped object.
KEY = "__envhub_pickle__"
#: The key of a plain info's numpy dtypes (JSON text: `{key: dtype}`).
TYPES = "__envhub_types__"

_PLAIN = (bool, int, float, str)
# Numpy scalar types that batch as their Python counterparts do (no `TYPES` entry needed).
_AS_PYTHON = (np.float64, np.int64)


class Encoded(dict):
    """An info `encode_info` made: plain JSON values already, so the worker dumps it as it
    is (`envhub.worker.info_json`) rather than checking every value again."""


@functools.lru_cache(maxsize=256)
def _types_text(types: tuple[tuple[str, str], ...]) -> str:
    return json.dumps(dict(types))


@functools.lru_cache(maxsize=256)
def _types_of(text: str) -> tuple[tuple[str, Any], ...]:
    return tuple((key, np.dtype(dtype).type) for key, dtype in json.loads(text).items())


def wrap(obj: Any) -> dict[str, str]:
    """`obj` as a JSON-safe one-key dict."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return {KEY: binascii.b2a_base64(data, newline=False).decode("ascii")}


def unwrap(value: Any) -> Any:
    """The object `wrap` wrapped; anything else is returned as it is."""
    if isinstance(value, dict) and KEY in value:
        return pickle.loads(binascii.a2b_base64(value[KEY]))
    return value


def encode_info(info: dict[str, Any] | None) -> dict[str, Any] | None:
    """An env's info as the worker sends it: plain JSON values (plus `TYPES`) when every
    value is a number, flag or text that JSON carries exactly, else wrapped whole; None
    when empty."""
    if not info:
        return None
    out = Encoded()
    types: list[tuple[str, str]] = []
    for key, value in info.items():
        if type(key) is not str or key in (KEY, TYPES, "final_info"):
            return wrap(info)
        t = type(value)
        if t not in _PLAIN:
            if not (isinstance(value, np.generic) and value.dtype.kind in "biuf"):
                return wrap(info)
            if t not in _AS_PYTHON:  # those batch as float and int do
                types.append((key, value.dtype.str))
            value = value.item()
        if type(value) is float and not math.isfinite(value):
            return wrap(info)  # JSON has no NaN or infinity
        if type(value) is int and not -(2**63) <= value < 2**63:
            return wrap(info)
        out[key] = value
    if types:
        out[TYPES] = _types_text(tuple(types))
    return out


def decode_info(info: dict[str, Any] | None) -> dict[str, Any]:
    """The info `encode_info` encoded."""
    if not info:
        return {}
    if KEY in info:
        return dict(unwrap(info))
    if TYPES not in info:
        return info
    out = dict(info)
    for key, scalar in _types_of(out.pop(TYPES)):
        out[key] = scalar(out[key])
    return out
