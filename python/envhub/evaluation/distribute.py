"""What every way of running shards elsewhere shares: the folder layout (`OUT/shards/shard-I`)
and the command line a shard runs (the evaluation's own arguments, less those that say where
and how it is distributed)."""

from __future__ import annotations

import os
from typing import Sequence

__all__ = ["SHARDS_DIR", "shard_folder", "shard_folders", "shard_argv"]

SHARDS_DIR = "shards"

#: The options that say how a run is distributed, with how many values each takes ("?": one
#: when the next word is not an option). A shard's own command line leaves them out and
#: sets `--shard`, `--out` and `--resume` itself.
DISTRIBUTION_OPTIONS = {
    "--ray": "?",
    "--shards": 1,
    "--ray-retries": 1,
    "--cpus-per-shard": 1,
    "--slurm-script": 1,
    "--slurm-option": 1,
    "--out": 1,
    "--shard": 1,
    "--resume": 0,
    "--report": 0,
    "--quiet": 0,
}


def shard_folder(out: str, index: int) -> str:
    return os.path.join(out, SHARDS_DIR, f"shard-{index}")


def shard_folders(out: str, count: int) -> list[str]:
    return [shard_folder(out, i) for i in range(count)]


def shard_argv(argv: Sequence[str]) -> list[str]:
    """`argv` (an `envhub eval` command line) without the distribution options."""
    out: list[str] = []
    words = list(argv)
    i = 0
    while i < len(words):
        word = words[i]
        name = word.split("=", 1)[0]
        takes = DISTRIBUTION_OPTIONS.get(name)
        if takes is None:
            out.append(word)
            i += 1
            continue
        i += 1
        if "=" in word:
            continue
        if takes == "?":
            if i < len(words) and not words[i].startswith("-"):
                i += 1
        else:
            i += int(takes)
    return out
