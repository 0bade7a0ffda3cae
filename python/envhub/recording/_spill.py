"""An episode's rows on disk, in the dataset's private staging folder, where no reader looks.

Rows past the writer's memory budget (`_rows.py`) go here in chunks. Each chunk stores every
column transposed, `(values per row, rows)`, so that both ways a commit reads an episode stay
cheap: a few rows of every value (a row group of the data file: one read per chunk) and every
row of a few values (the statistics' slices: one contiguous read per chunk). The commit copies
the rows into the data file and the file is removed; a crash leaves it in the staging folder,
which the next open empties.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: A chunk's bytes of one column, at most (one row at least).
CHUNK_BYTES = 2**20


class Spill:
    """The rows of one episode, appended in chunks of any number of rows."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.length = 0
        self._size = 0
        # Per chunk: its first row, its rows, and per column its offset in the file.
        self._chunks: list[tuple[int, int, dict[str, int]]] = []
        self._kinds: dict[str, tuple[np.dtype, int]] = {}  # per column: dtype, values per row
        path.touch()

    def append(self, columns: dict[str, np.ndarray]) -> None:
        """Rows `length..` (each column's first axis), in chunks of at most `CHUNK_BYTES` a
        column, so that reading a few rows reads at most that much more."""
        rows = len(next(iter(columns.values())))
        widest = max(v[:1].nbytes for v in columns.values())
        step = max(1, CHUNK_BYTES // max(widest, 1))
        with open(self.path, "ab") as f:
            for lo in range(0, rows, step):
                hi = min(lo + step, rows)
                offsets = {}
                for name, values in columns.items():
                    flat = values[lo:hi].reshape(hi - lo, -1)
                    self._kinds.setdefault(name, (values.dtype, flat.shape[1]))
                    offsets[name] = self._size
                    data = np.ascontiguousarray(flat.T).tobytes()
                    f.write(data)
                    self._size += len(data)
                self._chunks.append((self.length, hi - lo, offsets))
                self.length += hi - lo

    def width(self, name: str) -> int:
        """Values per row of column `name`."""
        return self._kinds[name][1]

    def dtype(self, name: str) -> np.dtype:
        return self._kinds[name][0]

    def _read(self, name: str, chunk: tuple[int, int, dict[str, int]], d0: int, d1: int) -> np.ndarray:
        """Values `d0..d1` of every row of a chunk, `(d1 - d0, rows)`."""
        dtype = self.dtype(name)
        _, rows, offsets = chunk
        count = (d1 - d0) * rows
        out = np.fromfile(self.path, dtype, count, offset=offsets[name] + d0 * rows * dtype.itemsize)
        if len(out) != count:
            raise OSError(f"`{self.path}` is shorter than the rows written to it")
        return out.reshape(d1 - d0, rows)

    def rows(self, name: str, lo: int, hi: int) -> np.ndarray:
        """Rows `lo..hi` (exclusive) of column `name`, `(hi - lo, values per row)`."""
        width = self.width(name)
        parts = []
        for chunk in self._chunks:
            first, rows, _ = chunk
            a, b = max(lo, first), min(hi, first + rows)
            if a < b:
                parts.append(np.ascontiguousarray(self._read(name, chunk, 0, width).T[a - first : b - first]))
        return np.concatenate(parts) if parts else np.empty((0, width), self.dtype(name))

    def values(self, name: str, d0: int, d1: int) -> np.ndarray:
        """Values `d0..d1` (of a row's values, flattened) of every row, `(length, d1 - d0)`."""
        out = np.empty((self.length, d1 - d0), self.dtype(name))
        for chunk in self._chunks:
            first, rows, _ = chunk
            out[first : first + rows] = self._read(name, chunk, d0, d1).T
        return out

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


class Spilled:
    """Column `name` of a spilled episode, where an episode's columns are arrays."""

    def __init__(self, spill: Spill, name: str) -> None:
        self.spill, self.name = spill, name

    def __len__(self) -> int:
        return self.spill.length


def rows_of(column: np.ndarray | Spilled, lo: int, hi: int) -> np.ndarray:
    """Rows `lo..hi` of an episode's column, in memory or spilled, `(hi - lo, values per row)`."""
    if isinstance(column, Spilled):
        return column.spill.rows(column.name, lo, hi)
    return column.reshape(len(column), -1)[lo:hi]


def values_of(column: np.ndarray | Spilled, d0: int, d1: int) -> np.ndarray:
    """Values `d0..d1` of every row of an episode's column, `(rows, d1 - d0)`."""
    if isinstance(column, Spilled):
        return column.spill.values(column.name, d0, d1)
    return column.reshape(len(column), -1)[:, d0:d1]


def width_of(column: np.ndarray | Spilled) -> int:
    """The values of a row of an episode's column."""
    if isinstance(column, Spilled):
        return column.spill.width(column.name)
    return int(np.prod(column.shape[1:], dtype=np.int64))


def row_bytes(column: np.ndarray | Spilled) -> int:
    """Bytes per row of an episode's column."""
    dtype = column.spill.dtype(column.name) if isinstance(column, Spilled) else column.dtype
    return width_of(column) * dtype.itemsize
