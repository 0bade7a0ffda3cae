"""The client's half of the typed info columns (`envhub.wire.info_schema` says the layout):
checks the schemas workers announce and reads rows with them, as Gymnasium's vector info."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import _envhub
from ..wire.info_schema import SCHEMA_KEY


class ColumnReader:
    """The client's half: checks announced schemas and reads rows with them."""

    def __init__(self, row_bytes: int, lookup: Callable[[int], Any] | None = None) -> None:
        self.row_bytes = row_bytes
        self.schemas: dict[int, tuple[np.dtype, list[tuple[str, str, int]], int, int]] = {}
        # A session takes announced schemas out of the infos itself, checks and keeps them
        # (`_envhub.Session.info_schema`); the reader asks it for one it has not seen.
        self.lookup = lookup

    def learn(self, infos: list[dict[str, Any]] | None) -> list[dict[str, Any]] | None:
        """Takes the schemas announced in `infos` out of them (checked, remembered); the
        infos left, None when none is left."""
        if not infos:
            return infos
        left: list[dict[str, Any]] = []
        for info in infos:
            if info and SCHEMA_KEY in info:
                info = dict(info)
                self._add(info.pop(SCHEMA_KEY))
            left.append(info)
        return left if any(left) else None

    def _add(self, text: Any) -> None:
        if not isinstance(text, str):
            raise ValueError("a worker announced an info-column schema that is not text")
        self._remember(*_envhub.info_schema(text, self.row_bytes))

    def _remember(self, sid: int, columns: list[tuple[str, str, list[int], int, int, str]]) -> None:
        names, formats, offsets, kinds = [], [], [], []
        for key, dtype, shape, offset, mask, kind in columns:
            names += [key, f"_{key}"]
            formats += [(np.dtype(dtype), tuple(shape)) if shape else np.dtype(dtype), np.dtype(np.bool_)]
            offsets += [offset, mask]
            kinds.append((key, kind, mask))
        dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": self.row_bytes})
        masks = [m for _, _, m in kinds]
        first = min(masks, default=0)
        contiguous = masks == list(range(first, first + len(masks)))
        if len(self.schemas) >= 256:
            self.schemas.pop(next(iter(self.schemas)))
        self.schemas[sid] = (dtype, kinds, first if contiguous else -1, len(masks))

    def _schema(self, sid: int) -> tuple[np.dtype, list[tuple[str, str, int]], int, int]:
        found = self.schemas.get(sid)
        if found is None and self.lookup is not None:
            described = self.lookup(sid)
            if described is not None:
                self._remember(*described)
                found = self.schemas.get(sid)
        if found is None:
            raise ValueError(f"info columns name schema {sid:#x}, which no worker announced")
        return found

    def ids(self, cols: np.ndarray) -> np.ndarray:
        return cols[:, :8].view(np.uint64)[:, 0]

    def columns(self, cols: np.ndarray, sid: int) -> dict[str, Any]:
        """Gymnasium's vector info of rows that all use schema `sid`: views of `cols`."""
        dtype, kinds, mask_at, k = self._schema(sid)
        n = len(cols)
        rec = cols.view(dtype)[:, 0] if n else np.zeros(0, dtype)
        if mask_at >= 0:
            flags = cols[:, mask_at : mask_at + k]
            if n and flags.max(initial=0) > 1:
                raise ValueError("info columns hold a presence flag other than 0 and 1")
            if n and flags.min() == 1:
                order = range(k)
            else:
                present = flags.any(axis=0)
                first = flags.argmax(axis=0)
                order = sorted((j for j in range(k) if present[j]), key=lambda j: (first[j], j))
        else:  # masks not side by side (not what this writer makes): look at each
            order = [j for j, (key, _, _) in enumerate(kinds) if rec[f"_{key}"].any()]
        out: dict[str, Any] = {}
        for j in order:
            key = kinds[j][0]
            out[key], out[f"_{key}"] = rec[key], rec[f"_{key}"]
        return out

    def env_info(self, cols: np.ndarray, k: int, sid: int) -> dict[str, Any]:
        """Env `k`'s info dict as the env returned it (values of their own Python types)."""
        dtype, kinds, _, _ = self._schema(sid)
        row = cols[k : k + 1].view(dtype)[0, 0]
        out: dict[str, Any] = {}
        for key, kind, _ in kinds:
            if row[f"_{key}"]:
                value = row[key]
                if kind == "py":
                    value = value.item()
                elif kind == "array":
                    value = np.array(value)
                out[key] = value
        return out
