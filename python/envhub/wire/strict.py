"""`zip_strict`: `zip(..., strict=True)` for the interpreters the worker side runs on.

`strict=` is Python 3.10's and the worker side runs down to CPython 3.9
(docs/design/architecture.md), where it is a `TypeError` the first time the line runs."""

from __future__ import annotations

from collections.abc import Iterator, Sized
from typing import Any

__all__ = ["zip_strict"]


def zip_strict(*sized: Sized) -> Iterator[tuple[Any, ...]]:
    """The tuples of `zip(*sized)`, after checking that every argument has the same length."""
    lengths = {len(s) for s in sized}
    if len(lengths) > 1:
        raise ValueError(f"zip_strict: arguments of different lengths {sorted(lengths)}")
    return zip(*sized)
