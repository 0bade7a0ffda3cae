"""The writer's rows of the episodes in flight, in memory bounded whatever the episodes' lengths.

A step's values go in with one copy per column, whatever the number of envs: columns are kept
time-major (`(steps, envs, ...)`) in blocks of up to `BLOCK` steps (fewer where a step's rows
are large: a block holds about `BLOCK_BYTES`). A full block is kept whole while at least half
of the envs' episodes in flight need rows of it; otherwise each env that does gets its own copy
of its rows, and the block goes. Once the rows held pass `SPILL_BYTES`, every episode in flight
has its rows appended to a file of its own in the dataset's staging folder (`_spill.py`) and
memory holds none of them: what is held stays under `SPILL_BYTES` plus a block, however long
the episodes.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ._spill import Spill, Spilled

#: Steps per block, at most.
BLOCK = 64
#: A block's bytes, about (one step at least).
BLOCK_BYTES = 2**20
#: The rows held in memory past which the episodes in flight go to their files.
SPILL_BYTES = 8 * 2**20


class Rows:
    """Rows `0, 1, ...` of every env, for the episodes in flight (`starts`, `live` when the
    rows are appended). `spill_path(env)` names a new file for an env's spilled rows."""

    def __init__(self, num_envs: int, spill_path: Callable[[int], Path]) -> None:
        self.n = num_envs
        self.count = 0  # rows appended
        self.block = BLOCK  # steps per block, set by the first step's size
        self.blocks: list[tuple[int, dict[str, np.ndarray]]] = []  # (first row, columns), oldest first
        # Per env, its rows taken out of blocks that went: (first row, columns).
        self.own: list[list[tuple[int, dict[str, np.ndarray]]]] = [[] for _ in range(num_envs)]
        # Per env, its episode's rows on disk (rows before `spilled[i]`), if any.
        self.spills: list[Spill | None] = [None] * num_envs
        self.origin = np.zeros(num_envs, dtype=np.int64)  # the spilled episode's first row
        self.spilled = np.zeros(num_envs, dtype=np.int64)
        self.names: list[str] = []
        self._spill_path = spill_path

    def append(self, values: dict[str, np.ndarray], starts: np.ndarray, live: np.ndarray) -> None:
        if not self.blocks or self.count - self.blocks[-1][0] == self.block:
            if not self.count:
                step = sum(np.asarray(v).nbytes for v in values.values())
                self.block = int(np.clip(BLOCK_BYTES // max(step, 1), 1, BLOCK))
                self.names = list(values)
            self._tidy(starts, live)
            self.blocks.append(
                (self.count, {k: np.empty((self.block, *np.shape(v)), np.asarray(v).dtype) for k, v in values.items()})
            )
        first, columns = self.blocks[-1]
        for k, v in values.items():
            columns[k][self.count - first] = v
        self.count += 1

    def _tidy(self, starts: np.ndarray, live: np.ndarray) -> None:
        """Before a new block: rows no episode in flight needs go, the episodes in flight go to
        their files if the rows held pass `SPILL_BYTES`, and a block fewer than half of the envs
        need is split into the envs' own rows."""
        for i in range(self.n):  # a file of an episode no longer in flight
            if self.spills[i] is not None and not (live[i] and starts[i] == self.origin[i]):
                self.forget(i)
        # Where each env's rows in memory begin (`count`: it needs none).
        begin = np.where(live, np.maximum(starts, self.spilled), self.count)
        for i in range(self.n):
            self.own[i] = [(f, c) for f, c in self.own[i] if f + _length(c) > begin[i]]
        held = sum(a.nbytes for _, c in self.blocks for a in c.values())
        held += sum(a.nbytes for own in self.own for _, c in own for a in c.values())
        if held > SPILL_BYTES:
            self._spill(begin)
            return
        kept = []
        for first, columns in self.blocks:
            need = np.flatnonzero(begin < first + self.block)
            if 2 * len(need) >= self.n:
                kept.append((first, columns))
                continue
            for i in need:
                lo = max(first, int(begin[i]))
                self.own[i].append((lo, {k: a[lo - first :, i].copy() for k, a in columns.items()}))
        self.blocks = kept

    def _spill(self, begin: np.ndarray) -> None:
        """Every episode in flight's rows in memory (all full blocks) appended to its file."""
        for i in np.flatnonzero(begin < self.count):
            if self.spills[i] is None:
                self.spills[i] = Spill(self._spill_path(int(i)))
                self.origin[i] = begin[i]
            self.spills[i].append({k: self._held(k, int(i), int(begin[i]), self.count) for k in self.names})
            self.own[i] = []
        self.spilled[begin < self.count] = self.count
        self.blocks = []

    def _held(self, name: str, env: int, start: int, end: int) -> np.ndarray:
        """Rows `start..end` (exclusive) of env `env`'s column `name` held in memory, a new array."""
        parts: list[tuple[int, np.ndarray]] = []
        for first, columns in self.own[env]:
            rows = columns[name]
            lo, hi = max(start, first), min(end, first + len(rows))
            if lo < hi:
                parts.append((lo, rows[lo - first : hi - first]))
        for first, columns in self.blocks:
            rows = columns[name]
            lo, hi = max(start, first), min(end, first + self.block, self.count)
            if lo < hi:
                parts.append((lo, rows[lo - first : hi - first, env]))
        parts.sort(key=lambda p: p[0])
        out = np.concatenate([p for _, p in parts])
        if len(out) != end - start:
            raise AssertionError(f"env {env}: rows {start}..{end} not all held ({len(out)})")
        return out

    def episode(self, names: list[str], env: int, start: int, end: int) -> dict[str, np.ndarray | Spilled]:
        """Env `env`'s episode, rows `start..end` (inclusive), by column: new arrays, or (for an
        episode that went to its file) the file's columns, which the env no longer owns."""
        spill = self.spills[env]
        if spill is None:
            columns = {k: self._held(k, env, start, end + 1) for k in names}
            self.forget(env)
            return columns
        lo = int(self.spilled[env])
        if lo <= end:
            spill.append({k: self._held(k, env, lo, end + 1) for k in self.names})
        self.spills[env] = None
        self.forget(env)
        if self.origin[env] != start or spill.length != end - start + 1:
            raise AssertionError(f"env {env}: rows {start}..{end} not all spilled ({spill.length})")
        return {k: Spilled(spill, k) for k in names}

    def forget(self, env: int) -> None:
        """Env `env`'s own rows go (its episode ended or was dropped), its file too."""
        self.own[env] = []
        if self.spills[env] is not None:
            self.spills[env].remove()
            self.spills[env] = None
        self.spilled[env] = 0


def _length(columns: dict[str, np.ndarray]) -> int:
    return len(next(iter(columns.values())))
