"""Spaces as `gymnasium.spaces`, and the flat byte layout values travel in.

The Rust side describes a space as JSON (`{"type": "box", ...}`) and, for each leaf, its byte
offset in a value. A leaf's values arrive as a typed array already; a `Dict`/`Tuple` arrives as
raw bytes per value and is split here into views of its leaves (no copy).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from .errors import InvalidActionError


def _bounds(values: list[Any], dtype: np.dtype) -> np.ndarray:
    if dtype.kind in "iu":
        # The bounds travel as doubles: an integer dtype's limits (2**63 - 1 rounds up to
        # 2**63) saturate at the dtype's range instead of wrapping around in the cast.
        info = np.iinfo(dtype)
        ints = []
        for v in values:
            f = float(v)
            ints.append(info.max if f >= info.max else info.min if f <= info.min else int(f))
        return np.array(ints, dtype=dtype)
    out = np.array([float(v) for v in values])  # numbers, or "inf" / "-inf"
    return out.astype(dtype) if dtype.kind == "f" else out


def to_gymnasium(desc: dict[str, Any]) -> spaces.Space[Any]:
    """A `gymnasium.spaces` space from its JSON description."""
    kind = desc["type"]
    if kind == "box":
        dtype = np.dtype(desc["dtype"])
        shape = tuple(desc["shape"])
        low = _bounds(desc["low"], dtype).reshape(shape)
        high = _bounds(desc["high"], dtype).reshape(shape)
        if dtype.kind != "f":
            low, high = low.astype(dtype), high.astype(dtype)
        return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)
    if kind == "discrete":
        return spaces.Discrete(int(desc["n"]), start=int(desc["start"]))
    if kind == "multi_discrete":
        shape = tuple(desc.get("shape") or (len(desc["nvec"]),))
        return spaces.MultiDiscrete(
            np.array(desc["nvec"], dtype=np.int64).reshape(shape),
            start=np.array(desc["start"], dtype=np.int64).reshape(shape),
        )
    if kind == "multi_binary":
        dims = list(desc["shape"])
        return spaces.MultiBinary(dims[0] if len(dims) == 1 else dims)
    if kind == "dict":
        return spaces.Dict({key: to_gymnasium(sub) for key, sub in desc["spaces"]})
    if kind == "tuple":
        return spaces.Tuple([to_gymnasium(sub) for sub in desc["spaces"]])
    raise ValueError(f"unknown space type `{kind}`")


def _describe(desc: dict[str, Any]) -> str:
    return str(to_gymnasium(desc))


@dataclass(frozen=True)
class _Leaf:
    offset: int
    nbytes: int
    dtype: np.dtype
    shape: tuple[int, ...]


def _tree(desc: dict[str, Any], leaves: list[dict[str, Any]]) -> Any:
    """The space's structure with its leaves, in layout order."""
    it = iter(leaves)

    def build(d: dict[str, Any]) -> Any:
        if d["type"] == "dict":
            return ("dict", [(key, build(sub)) for key, sub in d["spaces"]])
        if d["type"] == "tuple":
            return ("tuple", [build(sub) for sub in d["spaces"]])
        leaf = next(it)
        return _Leaf(int(leaf["offset"]), int(leaf["bytes"]), np.dtype(leaf["dtype"]), tuple(leaf["shape"]))

    return build(desc)


class Codec:
    """Turns raw results into observations and user actions into arrays, for one space pair.

    `batch` is the number of envs (the leading axis), or `None` for a single env.
    """

    def __init__(
        self,
        obs_desc: str,
        obs_leaves: str,
        act_desc: str,
        act_leaves: str,
        batch: int | None,
    ) -> None:
        self.obs_desc = json.loads(obs_desc)
        self.act_desc = json.loads(act_desc)
        self.obs_tree = _tree(self.obs_desc, json.loads(obs_leaves))
        self.act_tree = _tree(self.act_desc, json.loads(act_leaves))
        self.obs_composite = not isinstance(self.obs_tree, _Leaf)
        self.act_composite = not isinstance(self.act_tree, _Leaf)
        self.batch = batch
        lead = () if batch is None else (batch,)
        if not self.act_composite:
            leaf = self.act_tree
            self.act_dtype = leaf.dtype
            self.act_shape = lead + leaf.shape
            self.act_integer = leaf.dtype.kind in "iu"
        self.obs_space_text = _describe(self.obs_desc)
        self.act_space_text = _describe(self.act_desc)

    # Observations ---------------------------------------------------------------------------

    def obs(self, raw: np.ndarray) -> Any:
        """Observations from the array the session returned (views, no copy)."""
        if not self.obs_composite:
            return raw
        lead = raw.shape[:-1]

        def go(node: Any) -> Any:
            if isinstance(node, _Leaf):
                part = raw[..., node.offset : node.offset + node.nbytes].view(node.dtype)
                return part.reshape(lead + node.shape)
            kind, children = node
            if kind == "dict":
                return {key: go(child) for key, child in children}
            return tuple(go(child) for child in children)

        return go(self.obs_tree)

    def obs_from_bytes(self, data: np.ndarray) -> Any:
        """One env's observation from its bytes (`final_obs`, a uint8 array: a row of the
        slot lent with the step's other results, or the session's own copy): views of them."""
        if not self.obs_composite:
            leaf = self.obs_tree
            return data[: leaf.nbytes].view(leaf.dtype).reshape(leaf.shape)
        return self.obs(data)

    # Actions ------------------------------------------------------------------------------

    def actions(self, actions: Any, count: int | None = None) -> np.ndarray:
        """Actions as a C-contiguous array in the action space's dtype and layout; `count`
        overrides the number of envs (for `send` to some of them)."""
        n = self.batch if count is None else count
        lead: tuple[int, ...] = () if n is None else (n,)
        if self.act_composite:
            return self._pack(actions, lead)
        leaf = self.act_tree
        a = np.asarray(actions)
        if self.act_integer:
            if a.dtype.kind not in "iu":
                raise InvalidActionError(
                    f"actions are {a.dtype} but {self.act_space_text} takes integers\n"
                    f"hint: pass an integer array of shape {lead + leaf.shape}"
                )
        elif a.dtype.kind not in "fiu":
            raise InvalidActionError(
                f"actions are {a.dtype} but {self.act_space_text} takes numbers\n"
                f"hint: pass a float array of shape {lead + leaf.shape}"
            )
        if a.shape != lead + leaf.shape:
            raise InvalidActionError(
                f"actions have shape {a.shape} but {self.act_space_text} takes shape "
                f"{lead + leaf.shape}{' for ' + str(lead[0]) + ' envs' if lead else ''}\n"
                f"hint: pass one action per env, as `action_space.sample()` does"
            )
        return np.ascontiguousarray(a, dtype=leaf.dtype)

    def _pack(self, actions: Any, lead: tuple[int, ...]) -> np.ndarray:
        out = np.zeros(lead + (_value_bytes(self.act_tree),), dtype=np.uint8)

        def go(node: Any, value: Any, where: str) -> None:
            if isinstance(node, _Leaf):
                a = np.asarray(value)
                if a.shape != lead + node.shape:
                    raise InvalidActionError(
                        f"action{where} has shape {a.shape}; expected {lead + node.shape}\n"
                        f"hint: actions must match {self.act_space_text}"
                    )
                if node.dtype.kind in "iu" and a.dtype.kind not in "iu":
                    raise InvalidActionError(
                        f"action{where} is {a.dtype}; expected integers\n"
                        f"hint: actions must match {self.act_space_text}"
                    )
                flat = np.ascontiguousarray(a, dtype=node.dtype).reshape(lead + (-1,))
                out[..., node.offset : node.offset + node.nbytes] = flat.view(np.uint8)
                return
            kind, children = node
            if kind == "dict":
                for key, child in children:
                    try:
                        sub = value[key]
                    except (KeyError, TypeError, IndexError):
                        raise InvalidActionError(
                            f"action{where} has no key `{key}`\nhint: actions must match {self.act_space_text}"
                        ) from None
                    go(child, sub, f"{where}[{key!r}]")
            else:
                if len(value) != len(children):
                    raise InvalidActionError(
                        f"action{where} has {len(value)} parts; expected {len(children)}\n"
                        f"hint: actions must match {self.act_space_text}"
                    )
                for i, child in enumerate(children):
                    go(child, value[i], f"{where}[{i}]")

        go(self.act_tree, actions, "")
        return out


def _leaves(node: Any) -> list[_Leaf]:
    if isinstance(node, _Leaf):
        return [node]
    kind, children = node
    subtrees = [child for _, child in children] if kind == "dict" else children
    return [leaf for child in subtrees for leaf in _leaves(child)]


def _value_bytes(node: Any) -> int:
    """Bytes of one value of a composite: every child is padded to 8 bytes."""
    end = max((leaf.offset + leaf.nbytes for leaf in _leaves(node)), default=0)
    return (end + 7) // 8 * 8


def _bound_list(a: np.ndarray) -> list[Any]:
    out: list[Any] = []
    for v in np.asarray(a, dtype=np.float64).reshape(-1):
        out.append("inf" if v == np.inf else "-inf" if v == -np.inf else float(v))
    return out


_DTYPES = {"float32", "float64", "int8", "int32", "int64", "uint8", "bool"}


def from_gymnasium(space: spaces.Space[Any]) -> dict[str, Any]:
    """The JSON description of a `gymnasium.spaces` space (the inverse of `to_gymnasium`)."""
    if isinstance(space, spaces.Box):
        dtype = np.dtype(space.dtype).name
        if dtype not in _DTYPES:
            raise ValueError(f"Box dtype `{dtype}` is not supported; supported: {', '.join(sorted(_DTYPES))}")
        return {
            "type": "box",
            "dtype": dtype,
            "shape": list(space.shape),
            "low": _bound_list(space.low),
            "high": _bound_list(space.high),
        }
    if isinstance(space, spaces.Discrete):
        return {"type": "discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.MultiDiscrete):
        nvec = np.asarray(space.nvec)
        desc = {
            "type": "multi_discrete",
            "nvec": [int(v) for v in nvec.reshape(-1)],
            "start": [int(v) for v in np.asarray(space.start).reshape(-1)],
        }
        if nvec.ndim != 1:  # a 2-D nvec keeps its shape (the Rust space's `shape`)
            desc["shape"] = list(nvec.shape)
        return desc
    if isinstance(space, spaces.MultiBinary):
        return {"type": "multi_binary", "shape": list(np.atleast_1d(space.n))}
    if isinstance(space, spaces.Dict):
        return {"type": "dict", "spaces": [[k, from_gymnasium(s)] for k, s in space.spaces.items()]}
    if isinstance(space, spaces.Tuple):
        return {"type": "tuple", "spaces": [from_gymnasium(s) for s in space.spaces]}
    raise ValueError(f"space {space} is not supported; supported: Box, Discrete, MultiDiscrete, MultiBinary, Dict, Tuple")
