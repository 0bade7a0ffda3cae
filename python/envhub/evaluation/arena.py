"""Observations to a policy in another process (`--policy-env`) through shared memory.

The evaluation writes each batch's arrays into one memory file (`memfd`) that the policy's
process maps; the pipe carries the requests with every array replaced by its place
in that file (`Ref`). One copy per array, where pickling over a pipe makes three (into the
pickle, through the pipe, out of it) and a system call per 64 KiB. The file grows (doubling)
when a batch does not fit; the message says its size, and the reader maps it again.

What the policy is given are views, valid until its next `act` call (the next batch
overwrites them): a policy that keeps observations (a frame history) copies them. They are
writable, as in-process observations are (Meta-World's scripted policies write into theirs);
what a policy writes there is overwritten by the next batch and never read back.
"""

from __future__ import annotations

import mmap
import os
from dataclasses import replace
from typing import Any, NamedTuple, Sequence

import numpy as np

__all__ = ["Arena", "ArenaView", "Ref"]

ALIGN = 64  # a cache line: every array starts on one
PAGE = mmap.PAGESIZE


class Ref(NamedTuple):
    """An array at `offset` of the arena."""

    offset: int
    dtype: str
    shape: tuple


def _round(n: int, to: int) -> int:
    return (n + to - 1) // to * to


class Arena:
    """The evaluation's side: a memory file that batches are written into (`fd`, passed to
    the policy's process)."""

    def __init__(self, capacity: int = 1 << 20) -> None:
        self.fd = os.memfd_create("envhub-policy-observations")
        self.capacity = 0
        self._map: mmap.mmap | None = None
        self._grow(capacity)

    def _grow(self, need: int) -> None:
        capacity = _round(max(need, 2 * self.capacity), PAGE)
        os.ftruncate(self.fd, capacity)
        # The old mapping is dropped, not closed: arrays may still view it (it goes with them).
        self._map = mmap.mmap(self.fd, capacity)
        self.capacity = capacity

    def put(self, requests: Sequence[Any]) -> tuple[list[Any], int]:
        """The requests with their observations' arrays written here (replaced by `Ref`s),
        and the arena's size the reader must map."""
        placed: list[tuple[np.ndarray, int]] = []
        end = 0

        def place(value: Any) -> Any:
            nonlocal end
            if isinstance(value, np.ndarray) and not value.dtype.hasobject:
                placed.append((value, end))
                ref = Ref(end, value.dtype.str, tuple(value.shape))
                end = _round(end + value.nbytes, ALIGN)
                return ref
            if isinstance(value, dict):
                return {k: place(v) for k, v in value.items()}
            if isinstance(value, (list, tuple)):
                return type(value)(place(v) for v in value)
            return value

        shaped = [place(r.observation) for r in requests]
        if end > self.capacity:
            self._grow(end)
        assert self._map is not None
        for a, offset in placed:
            if a.nbytes:
                np.frombuffer(self._map, a.dtype, a.size, offset).reshape(a.shape)[...] = a
        return [replace(r, observation=o) for r, o in zip(requests, shaped)], self.capacity

    def close(self) -> None:
        if self._map is not None:
            self._map = None
            os.close(self.fd)


class ArenaView:
    """The policy's side: the arena mapped (shared), and requests given their arrays back."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.size = 0
        self._map: mmap.mmap | None = None

    def take(self, requests: Sequence[Any], size: int) -> list[Any]:
        if size > self.size:
            # The old mapping is dropped, not closed: a policy may still hold views of it.
            self._map = mmap.mmap(self.fd, size)
            self.size = size

        def view(value: Any) -> Any:
            if isinstance(value, Ref):
                dtype = np.dtype(value.dtype)
                count = int(np.prod(value.shape, dtype=np.int64))
                if count == 0:
                    return np.empty(value.shape, dtype)
                return np.frombuffer(self._map, dtype, count, value.offset).reshape(value.shape)
            if isinstance(value, dict):
                return {k: view(v) for k, v in value.items()}
            if isinstance(value, (list, tuple)):
                return type(value)(view(v) for v in value)
            return value

        return [replace(r, observation=view(r.observation)) for r in requests]
