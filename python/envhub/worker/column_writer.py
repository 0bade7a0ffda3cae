"""The worker's half of the typed info columns (`envhub.wire.info_schema` says the layout):
learns a schema from its envs' infos and packs each info that fits into the env's row of the
slot, in one `struct.pack_into`."""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..wire.info_schema import SCHEMA_KEY
from ..wire.strict import zip_strict

# Keys that never go into a column: the data plane's own, and Gymnasium's same_step keys.
_RESERVED = frozenset({SCHEMA_KEY, "__envhub_pickle__", "__envhub_types__", "final_info", "final_obs"})

# Python scalar types and numpy scalar types that Gymnasium batches into a typed array.
_PY_CODES: dict[type, tuple[str, str]] = {bool: ("?", "|b1"), int: ("q", "<i8"), float: ("d", "<f8")}
_NP_CODES: dict[type, str] = {
    np.float64: "d",
    np.float32: "f",
    np.float16: "e",
    np.int8: "b",
    np.int16: "h",
    np.int32: "i",
    np.int64: "q",
    np.uint8: "B",
    np.uint16: "H",
    np.uint32: "I",
    np.uint64: "Q",
}
_ARRAY_DTYPES = frozenset({"|b1", "|i1", "|u1", "<i2", "<u2", "<f2", "<i4", "<u4", "<f4", "<i8", "<u8", "<f8"})
# At most this many schemas per worker: infos whose keys keep changing take the JSON path.
_MAX_SCHEMAS = 16


class _Schema:
    """A learned layout: keys in order, each value's struct code, and where it lies."""

    def __init__(self, keys: list[str], specs: list[tuple[str, str, tuple[int, ...], str, Any]], row_bytes: int):
        self.keys = tuple(keys)
        self.index = {k: j for j, k in enumerate(keys)}
        self.types = tuple(spec[4] for spec in specs)  # exact Python types of the values
        self.specs = specs
        fmt, offset, columns = ["<Q"], 8, []
        for key, (code, dtype, shape, kind, _) in zip_strict(keys, specs):
            item = np.dtype(dtype).itemsize
            size = item * int(np.prod(shape, dtype=np.int64))
            pad = -offset % item
            if pad:
                fmt.append(f"{pad}x")
            offset += pad
            columns.append({"key": key, "dtype": dtype, "shape": list(shape), "offset": offset, "kind": kind})
            fmt.append(code if kind != "array" else f"{size}s")
            offset += size
        for j, c in enumerate(columns):
            c["mask"] = offset + j
        fmt.append(f"{len(keys)}s")
        offset += len(keys)
        self.fits_row = offset <= row_bytes
        self.struct = struct.Struct("".join(fmt))
        self.all_present = b"\x01" * len(keys)
        self.has_arrays = any(spec[3] == "array" for spec in specs)
        self.zeros = tuple(_zero(spec) for spec in specs)
        # The id is the layout's hash: workers that learn the same layout write the same id,
        # so a batch over several workers is still one set of column views.
        layout = json.dumps(columns)
        self.id = int.from_bytes(hashlib.blake2b(layout.encode(), digest_size=8).digest(), "little") | 1
        self.text = f'{{"id": {self.id}, "keys": {layout}}}'


def _zero(spec: tuple[str, str, tuple[int, ...], str, Any]) -> Any:
    code, dtype, shape, kind, _ = spec
    if kind == "array":
        return bytes(np.dtype(dtype).itemsize * int(np.prod(shape, dtype=np.int64)))
    return False if code == "?" else 0


def _spec(value: Any) -> tuple[str, str, tuple[int, ...], str, Any] | None:
    """How `value` goes into a column, or None when it does not."""
    t = type(value)
    if t in _PY_CODES:
        code, dtype = _PY_CODES[t]
        return code, dtype, (), "py", t
    np_code = _NP_CODES.get(t)
    if np_code is not None:
        return np_code, value.dtype.str, (), "np", t
    if t is np.ndarray and value.dtype.str in _ARRAY_DTYPES and value.ndim <= 8:
        return "", value.dtype.str, value.shape, "array", t
    return None


class ColumnWriter:
    """The worker's half: writes each env's info into its row, or says it does not fit."""

    def __init__(self, row_bytes: int) -> None:
        self.row_bytes = row_bytes
        self.schema: _Schema | None = None
        self.made = 0
        self.announced: set[int] = set()
        self._zero_id = struct.Struct("<Q")

    def write(self, rows: memoryview, i: int, info: dict[str, Any]) -> str | None | bool:
        """Writes env `i`'s info into row `i` of `rows`. Returns False when it does not fit
        (the row then says so: the info goes as JSON), else the schema's text when it is new
        to the client (to announce in this env's JSON info) or None."""
        s = self.schema
        at = i * self.row_bytes
        if s is None or not self._pack(s, rows, at, info):
            s = self._learn(info)
            if s is None or not self._pack(s, rows, at, info):
                self._zero_id.pack_into(rows, at, 0)
                return False
        if s.id in self.announced:
            return None
        self.announced.add(s.id)
        return s.text

    def skip(self, rows: memoryview, i: int) -> None:
        """Marks row `i` as carrying no columns (an env not stepped, or whose info is JSON)."""
        self._zero_id.pack_into(rows, i * self.row_bytes, 0)

    def _pack(self, s: _Schema, rows: memoryview, at: int, info: dict[str, Any]) -> bool:
        values: Iterable[Any] = info.values()
        try:
            if tuple(info) == s.keys and tuple(map(type, values)) == s.types:
                if s.has_arrays:
                    if not self._arrays_match(s, info):
                        return False
                    values = [v.tobytes() if type(v) is np.ndarray else v for v in values]
                s.struct.pack_into(rows, at, s.id, *values, s.all_present)
                return True
            # Some keys absent: in the schema's order, of its types.
            packed, present, last = list(s.zeros), bytearray(len(s.keys)), -1
            for key, value in info.items():
                j = s.index.get(key, -1) if type(key) is str else -1
                if j <= last or type(value) is not s.types[j]:
                    return False
                if type(value) is np.ndarray:
                    _, dtype, shape, _, _ = s.specs[j]
                    if value.dtype.str != dtype or value.shape != shape:
                        return False
                    value = value.tobytes()
                packed[j], present[j], last = value, 1, j
            s.struct.pack_into(rows, at, s.id, *packed, bytes(present))
            return True
        except (struct.error, OverflowError, TypeError):
            return False  # an int beyond int64, say: Gymnasium's own path decides

    @staticmethod
    def _arrays_match(s: _Schema, info: dict[str, Any]) -> bool:
        for value, (_, dtype, shape, kind, _) in zip_strict(info.values(), s.specs):
            if kind == "array" and (value.dtype.str != dtype or value.shape != shape):
                return False
        return True

    def _learn(self, info: dict[str, Any]) -> _Schema | None:
        """A schema for `info`, merged with the current one where their keys agree in order
        and type (a reset's info is often a prefix of a step's); None when it cannot have
        one."""
        if self.made >= _MAX_SCHEMAS or not info:
            return None
        specs = {}
        for key, value in info.items():
            if type(key) is not str or not key or key.startswith("_") or key in _RESERVED:
                return None
            spec = _spec(value)
            if spec is None:
                return None
            specs[key] = spec
        keys = list(specs)
        old = self.schema
        if old is not None and all(k not in specs or specs[k][1:] == old.specs[j][1:] for j, k in enumerate(old.keys)):
            common = [k for k in keys if k in old.index]
            if [k for k in old.keys if k in specs] == common:
                merged = list(old.keys) + [k for k in keys if k not in old.index]
                spec_of = {**dict(zip_strict(old.keys, old.specs)), **specs}
                # The info's own keys must keep its order in the merged list.
                positions = [merged.index(k) for k in keys]
                if positions == sorted(positions):
                    keys = merged
                    specs = {k: spec_of[k] for k in merged}
        schema = _Schema(keys, [specs[k] for k in keys], self.row_bytes)
        if not schema.fits_row:
            return None
        self.made += 1
        self.schema = schema
        return schema
