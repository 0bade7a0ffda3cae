"""The queue between the stepping thread and the writer, bounded in bytes.

A step of 64 envs with 480x480 frames is 44 MB, a step of CartPole's 64 states 1 KB: a bound
in items says nothing about memory. This one counts the bytes of every item from `put` until
the writer says it is `done` with it (so the step being written counts too). An item larger
than the whole budget still goes in, alone, so no step can wait forever.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from typing import Any

#: The default budget: 512 MiB.
DEFAULT_QUEUE_BYTES = 512 * 2**20


class ByteQueue:
    def __init__(self, budget: int) -> None:
        self.budget = int(budget)
        self.used = 0  # bytes of the items queued or being written
        self.peak = 0
        self._items: deque[tuple[Any, int]] = deque()
        self._cond = threading.Condition()

    def put(self, item: Any, nbytes: int, timeout: float | None = None) -> bool:
        """Queues `item` once its `nbytes` fit the budget; `False` if they did not within
        `timeout` seconds (0: do not wait)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while self.used and self.used + nbytes > self.budget:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return False
                self._cond.wait(left)
            self._items.append((item, nbytes))
            self.used += nbytes
            self.peak = max(self.peak, self.used)
            self._cond.notify_all()
            return True

    def get(self, timeout: float | None = None) -> tuple[Any, int]:
        """The oldest item and its size; `queue.Empty` after `timeout` seconds without one."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while not self._items:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise queue.Empty
                self._cond.wait(left)
            return self._items.popleft()

    def done(self, nbytes: int) -> None:
        """The writer is done with an item of `nbytes`: its bytes leave the budget."""
        with self._cond:
            self.used -= nbytes
            self._cond.notify_all()
