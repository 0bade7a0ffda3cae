"""The writer's rows of the episodes in flight, in memory bounded by what those episodes hold.

A step's values go in with one copy per column, whatever the number of envs: columns are kept
time-major (`(steps, envs, ...)`) in blocks of `BLOCK` steps. A full block is kept whole while
at least half of the envs' episodes in flight need rows of it; otherwise each env that does
gets its own copy of its rows (one copy per env and block), and the block goes. So one long
episode keeps its own rows, not every env's since it began: what is held is at most twice the
rows the episodes in flight have, plus the newest blocks.
"""

from __future__ import annotations

import numpy as np

#: Steps per block.
BLOCK = 64


class Rows:
    """Rows `0, 1, ...` of every env, for the episodes in flight (`starts`, `live` when the
    rows are appended)."""

    def __init__(self, num_envs: int) -> None:
        self.n = num_envs
        self.count = 0  # rows appended
        self.blocks: list[tuple[int, dict[str, np.ndarray]]] = []  # (first row, columns), oldest first
        # Per env, its rows taken out of blocks that went: (first row, columns).
        self.own: list[list[tuple[int, dict[str, np.ndarray]]]] = [[] for _ in range(num_envs)]

    def append(self, values: dict[str, np.ndarray], starts: np.ndarray, live: np.ndarray) -> None:
        if not self.blocks or self.count - self.blocks[-1][0] == BLOCK:
            self._tidy(starts, live)
            self.blocks.append(
                (self.count, {k: np.empty((BLOCK, *np.shape(v)), np.asarray(v).dtype) for k, v in values.items()})
            )
        first, columns = self.blocks[-1]
        for k, v in values.items():
            columns[k][self.count - first] = v
        self.count += 1

    def _tidy(self, starts: np.ndarray, live: np.ndarray) -> None:
        """Before a new block: rows no episode in flight needs go, and a block fewer than half
        of the envs need is split into the envs' own rows."""
        for i in range(self.n):
            start = starts[i] if live[i] else self.count
            self.own[i] = [(f, c) for f, c in self.own[i] if f + len(next(iter(c.values()))) > start]
        kept = []
        for first, columns in self.blocks:
            need = np.flatnonzero(live & (starts < first + BLOCK))
            if 2 * len(need) >= self.n:
                kept.append((first, columns))
                continue
            for i in need:
                lo = max(first, int(starts[i]))
                self.own[i].append((lo, {k: a[lo - first :, i].copy() for k, a in columns.items()}))
        self.blocks = kept

    def episode(self, name: str, env: int, start: int, end: int) -> np.ndarray:
        """Rows `start..end` (inclusive) of env `env`'s column `name`, a new array."""
        parts: list[tuple[int, np.ndarray]] = []
        for first, columns in self.own[env]:
            rows = columns[name]
            lo, hi = max(start, first), min(end + 1, first + len(rows))
            if lo < hi:
                parts.append((lo, rows[lo - first : hi - first]))
        for first, columns in self.blocks:
            rows = columns[name]
            lo, hi = max(start, first), min(end + 1, first + BLOCK, self.count)
            if lo < hi:
                parts.append((lo, rows[lo - first : hi - first, env]))
        parts.sort(key=lambda p: p[0])
        out = np.concatenate([p for _, p in parts])
        if len(out) != end - start + 1:
            raise AssertionError(f"env {env}: rows {start}..{end} not all held ({len(out)})")
        return out

    def forget(self, env: int) -> None:
        """Env `env`'s own rows go (its episode ended or was dropped)."""
        self.own[env] = []
