"""Giving memory back after a commit.

A commit allocates many times its rows for a moment (Arrow's tables and Parquet's buffers, the
statistics' temporaries), and neither Arrow's allocator (mimalloc in pyarrow's wheels) nor
glibc's hands freed memory back to the system by itself: without this, the resident set keeps
the largest commit's peak for good, and a file written or joined a row group at a time grows
by every group. Both are asked to after every row group a commit or a join writes and after
every commit; each is a no-op where it does not apply (another allocator, another C library).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from typing import Any

_trim: Any = None  # glibc's `malloc_trim`, looked up once (False: none here)


def release() -> None:
    """Returns the memory freed since the last call to the system, as far as the allocators can."""
    global _trim
    import pyarrow as pa

    pa.default_memory_pool().release_unused()
    if _trim is None:
        try:
            _trim = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
            _trim.argtypes, _trim.restype = [ctypes.c_size_t], ctypes.c_int
        except (OSError, AttributeError):  # not glibc
            _trim = False
    if _trim:
        _trim(0)
