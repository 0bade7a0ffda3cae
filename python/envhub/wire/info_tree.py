"""Nested infos through the data plane, exactly and without pickle.

The data plane carries an env's info as flat JSON of numbers, flags, text and short vectors.
Suites such as MyoSuite report nested dicts of numpy arrays and scalars (`obs_dict`,
`rwd_dict`), and Meta-World a dict of episode statistics at the end of an episode. A hosted
env whose info holds anything but Python's own `bool`, `int`, `float` and `str` sends it as one
text value under `KEY`: a JSON tree in which every numpy array and scalar keeps its dtype,
shape and bytes (base64), and dicts, lists and tuples keep their kind. The client turns it
back into the same objects. JSON and base64 rather than pickle: a client may talk to a remote
hub, and decoding must not run code the other side chose.
"""

from __future__ import annotations

import base64
import json
import math
from typing import Any

import numpy as np

#: The info key of an encoded tree.
KEY = "__envhub_info_tree__"

_PLAIN = (bool, int, float, str)


def encode(info: dict[str, Any] | None) -> dict[str, Any] | None:
    """`info` as the worker sends it: unchanged when every value is a Python `bool`, `int`,
    `float` (finite) or `str` and every key a `str`, else `{KEY: <JSON tree>}`."""
    if not info:
        return info
    if all(type(k) is str and _plain(v) for k, v in info.items()):
        return info
    return {KEY: json.dumps(_node(info), separators=(",", ":"))}


def decode(info: Any) -> Any:
    """The info `encode` encoded (anything else is returned as it is)."""
    if isinstance(info, dict) and KEY in info:
        return _value(json.loads(info[KEY]))
    return info


def _plain(v: Any) -> bool:
    t = type(v)
    if t is float:
        return math.isfinite(v)
    if t is int:
        return -(2**63) <= v < 2**63
    return t in _PLAIN


def _bytes(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _node(v: Any) -> Any:
    """A JSON value for `v`: plain JSON for Python scalars, a one-key object naming the kind
    for everything else (so a decoded object is never mistaken for a dict)."""
    t = type(v)
    if v is None or t is bool or t is str:
        return v
    if t is int:
        return v if -(2**63) <= v < 2**63 else {"bigint": str(v)}
    if t is float:
        return v if math.isfinite(v) else {"float": repr(v)}
    if isinstance(v, np.ndarray) and v.dtype.kind in "biufc":
        return {"ndarray": [v.dtype.str, list(v.shape), _bytes(v)]}
    if isinstance(v, np.generic) and v.dtype.kind in "biufc":
        return {"scalar": [v.dtype.str, _bytes(np.asarray(v))]}
    if isinstance(v, dict):
        return {"dict": [[_node(k), _node(x)] for k, x in v.items()]}
    if isinstance(v, tuple):
        return {"tuple": [_node(x) for x in v]}
    if isinstance(v, (list, np.ndarray)):
        return {"list": [_node(x) for x in v]}
    for base in (bool, int, float, str):  # subclasses (enums, ...) as their base type
        if isinstance(v, base):
            return _node(base(v))
    return {"repr": repr(v)}


def _value(n: Any) -> Any:
    if not isinstance(n, dict):
        return n
    ((kind, body),) = n.items()
    if kind == "ndarray":
        dtype, shape, data = body
        return np.frombuffer(base64.b64decode(data), dtype=np.dtype(dtype)).reshape(shape).copy()
    if kind == "scalar":
        dtype, data = body
        return np.frombuffer(base64.b64decode(data), dtype=np.dtype(dtype))[0]
    if kind == "dict":
        return {_value(k): _value(x) for k, x in body}
    if kind == "tuple":
        return tuple(_value(x) for x in body)
    if kind == "list":
        return [_value(x) for x in body]
    if kind == "float":
        return float(body)
    if kind == "bigint":
        return int(body)
    return body  # "repr": the text of an object JSON cannot carry
