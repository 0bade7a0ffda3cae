"""Shards of an evaluation: `--shard I/N` runs a deterministic slice of a benchmark's
episodes, and `merge` joins the shards' folders into the table one machine would have made.

A shard is a slice of the episode list in the benchmark's own order (task by task, each
task's episodes by index): shard I of N takes the I-th of N contiguous, near-equal runs of
it. The slice depends on (tasks, episodes per task, I, N) alone, never on which machine runs
it or when, so shard I run twice (or resumed elsewhere) runs the same episodes. Contiguous
runs keep a task's episodes together: a task's session (its workers, the suite's import)
starts in as few shards as possible.

Every episode's result depends on (benchmark, task, episode index, policy) alone, so the
merged table equals the one-machine table row for row; `merge` refuses what would break that
(shards of different benchmarks, protocols, policies or versions; overlapping, missing or
unfinished shards; a shard folder still being written) with an error that names the folder.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from typing import Any, Sequence

from .benchmarks import Benchmark, BenchmarkError
from .results import LOG, RUN, FolderLock, FolderLocked, read_log

__all__ = ["Shard", "ShardError", "episode_keys", "parse_shard"]

RESULTS = "results.json"


class ShardError(BenchmarkError):
    """A shard option or a set of shard folders that cannot be merged; the message names
    what is wrong and how to fix it."""


@dataclass(frozen=True)
class Shard:
    """Shard `index` (0-based) of `count`."""

    index: int
    count: int

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"

    def as_dict(self) -> dict[str, int]:
        return {"index": self.index, "count": self.count}

    def bounds(self, total: int) -> tuple[int, int]:
        """This shard's slice `[lo, hi)` of a list of `total` episodes."""
        return (total * self.index) // self.count, (total * (self.index + 1)) // self.count

    def keys(self, bench: Benchmark) -> list[str]:
        """This shard's episodes (`<task id>#<index>`), in the benchmark's order."""
        every = episode_keys(bench)
        lo, hi = self.bounds(len(every))
        return every[lo:hi]


def parse_shard(text: str) -> Shard:
    """`I/N` with 0 <= I < N (Slurm's `$SLURM_ARRAY_TASK_ID/N` with `--array=0-(N-1)`)."""
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text or "")
    if m is None:
        raise ShardError(f"--shard `{text}`: give I/N, shard I (0 to N-1) of N, as 0/4 ... 3/4")
    index, count = int(m.group(1)), int(m.group(2))
    if count < 1 or index >= count:
        raise ShardError(f"--shard `{text}`: I must be 0 to N-1 and N at least 1 (valid for N={max(count, 1)}: "
                         f"0/{max(count, 1)} to {max(count, 1) - 1}/{max(count, 1)})")
    return Shard(index, count)


def episode_keys(bench: Benchmark) -> list[str]:
    """Every episode of `bench` in its order: task by task, each task's episodes by index."""
    return [f"{t.id}#{k}" for t in bench.tasks for k in range(bench.episodes_per_task)]


# Merging -------------------------------------------------------------------------------------


@dataclass
class ShardRun:
    """A shard's folder as read for a merge: its header, results and episode records."""

    folder: str
    header: dict[str, Any]
    shard: Shard
    results: dict[str, Any]
    records: dict[str, dict[str, Any]]


def _load_json(path: str, what: str) -> Any:
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as e:
        raise ShardError(f"{what}: cannot read {path}: {type(e).__name__}: {e}") from None


def read_shard(folder: str) -> ShardRun:
    """One shard's folder, checked: an evaluation run with `--shard`, not being written, and
    finished (its `results.json` written after its last episode)."""
    if not os.path.isdir(folder):
        raise ShardError(f"shard folder {folder} does not exist")
    try:
        header = _load_json(os.path.join(folder, RUN), f"shard folder {folder}")
    except FileNotFoundError:
        raise ShardError(f"{folder} holds no evaluation (no {RUN}): give the --out folders of `envhub eval --shard I/N`") from None
    if not isinstance(header, dict) or "shard" not in header:
        raise ShardError(f"{folder} holds an evaluation run without --shard: only the folders of `envhub eval --shard I/N` merge")
    try:
        FolderLock(folder).release()
    except FolderLocked as e:
        raise ShardError(f"shard {folder} is still being written: {str(e).splitlines()[0]}\n"
                         "hint: merge once every shard's evaluation has ended") from None
    except OSError:
        pass  # a filesystem without flock (or read-only): the checks of a finished shard below still hold
    try:
        results = _load_json(os.path.join(folder, RESULTS), f"shard folder {folder}")
    except FileNotFoundError:
        results = None
    s = header["shard"]
    shard = Shard(int(s["index"]), int(s["count"]))
    records = read_log(os.path.join(folder, LOG))
    if results is None or len(results.get("episodes", [])) != len(records):
        raise ShardError(f"shard {shard} in {folder} did not finish ({len(records)} episodes logged, no final results)\n"
                         f"hint: run the same `envhub eval ... --shard {shard} --out {folder} --resume` to finish it")
    return ShardRun(folder, header, shard, results, records)


def _comparable(header: dict[str, Any]) -> dict[str, Any]:
    """A shard's header less what may differ between machines running one evaluation: the
    shard, and where the benchmark's declaration was read (`protocol.source`, a path)."""
    out = {k: v for k, v in header.items() if k != "shard"}
    if isinstance(out.get("protocol"), dict):
        out["protocol"] = {k: v for k, v in out["protocol"].items() if k != "source"}
    return out


def _differs(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    return sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))


def check_shards(runs: Sequence[ShardRun]) -> int:
    """Checks that `runs` are the N shards of one evaluation, each once; returns N."""
    if not runs:
        raise ShardError("give the shard folders to merge")
    first = runs[0]
    base = _comparable(first.header)
    for r in runs[1:]:
        other = _comparable(r.header)
        if other != base:
            raise ShardError(f"{r.folder} is not a shard of the evaluation in {first.folder}: they differ in "
                             f"{', '.join(_differs(base, other))} (benchmark, protocol, tasks and policy must be equal)")
        if r.results.get("versions") != first.results.get("versions"):
            a, b = first.results.get("versions") or {}, r.results.get("versions") or {}
            raise ShardError(f"{r.folder} ran with other versions than {first.folder} ({', '.join(_differs(a, b))} differ: "
                             f"{ {k: a.get(k) for k in _differs(a, b)} } vs { {k: b.get(k) for k in _differs(a, b)} }): "
                             "a merged table must come from one set of versions")
    counts = sorted({r.shard.count for r in runs})
    if len(counts) > 1:
        raise ShardError(f"the shards split the evaluation in different ways (N = {', '.join(map(str, counts))}): "
                         + ", ".join(f"{r.folder} is {r.shard}" for r in runs))
    n = counts[0]
    seen: dict[int, str] = {}
    for r in runs:
        if r.shard.index in seen:
            raise ShardError(f"shard {r.shard} is given twice: {seen[r.shard.index]} and {r.folder} (give each shard once)")
        seen[r.shard.index] = r.folder
    missing = [i for i in range(n) if i not in seen]
    if missing:
        raise ShardError(f"shards {', '.join(f'{i}/{n}' for i in missing)} are missing (given: "
                         f"{', '.join(f'{i}/{n}' for i in sorted(seen))}): a merge needs all {n}")
    return n


def merged_records(runs: Sequence[ShardRun], bench_keys: list[str]) -> list[dict[str, Any]]:
    """Every shard's records, checked to be its slice and nothing else, in the benchmark's order."""
    out: dict[str, dict[str, Any]] = {}
    for r in runs:
        lo, hi = r.shard.bounds(len(bench_keys))
        mine = set(bench_keys[lo:hi])
        extra = sorted(set(r.records) - mine)
        lacking = [k for k in bench_keys[lo:hi] if k not in r.records]
        if extra or lacking:
            detail = f"episodes outside its slice: {', '.join(extra[:5])}" if extra else f"missing {', '.join(lacking[:5])}"
            raise ShardError(f"shard {r.shard} in {r.folder} does not hold its slice ({detail})")
        for k in mine:
            rec = dict(r.records[k])
            if rec.get("video"):
                # Relative to the shard's folder; the merged table names it from the merged one.
                rec["video"] = os.path.join(os.path.abspath(r.folder), rec["video"])
            out[k] = rec
    return [out[k] for k in bench_keys]
