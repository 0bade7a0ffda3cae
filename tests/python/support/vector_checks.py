"""Checks that the client tests share: exact equality of two vector envs' results, and where
an array's bytes live (inside a `/dev/shm` mapping of this process, the batch slot owning it)."""

from __future__ import annotations

from typing import Any

import numpy as np

#: The step timeout of the drop-in comparisons: far above any wait a loaded machine causes.
STEP_TIMEOUT = 60.0


def assert_same(a: Any, b: Any, where: str) -> None:
    """Exact equality of two results (arrays, dtypes, dicts, object arrays of them)."""
    if isinstance(b, dict):
        assert isinstance(a, dict) and a.keys() == b.keys(), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for k in b:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(b, tuple):
        assert isinstance(a, tuple) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray), f"{where}: {type(a)} is not an array"
        assert a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a.dtype}{a.shape} != {b.dtype}{b.shape}"
        if b.dtype == object:
            for i, (x, y) in enumerate(zip(a.reshape(-1), b.reshape(-1), strict=True)):
                assert_same(x, y, f"{where}.flat[{i}]")
        else:
            assert np.array_equal(a, b, equal_nan=b.dtype.kind in "fc"), f"{where}: {a} != {b}"
    else:
        assert type(a) is type(b) and (a == b or (a != a and b != b)), f"{where}: {a!r} != {b!r}"


def address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def shm_mappings() -> list[tuple[int, int, str]]:
    """(start, end, path) of this process's mappings of files in /dev/shm."""
    out = []
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 6 and parts[5].startswith("/dev/shm/"):
                lo, hi = (int(x, 16) for x in parts[0].split("-"))
                out.append((lo, hi, parts[5]))
    return out


def in_shared_memory(a: np.ndarray) -> str | None:
    at = address(a)
    return next((path for lo, hi, path in shm_mappings() if lo <= at and at + a.nbytes <= hi), None)


def slot_of(a: np.ndarray):
    """The owner object at the root of an array's bases, if it is envhub's."""
    base = a
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    return base if type(base).__name__ == "SharedSlot" else None
