"""`envhub eval merge OUT SHARD...`: the shards' folders of one evaluation joined into the
results one machine would have written (`results.json`, `results.csv`, `tasks.csv`,
`episodes.jsonl`, `run.json`; `report.html` when asked), with each shard's time and host."""

from __future__ import annotations

import json
import os
from typing import Any, Sequence

from .axes import axis_rows
from .results import LOG, RUN, FolderLock, _write_json, summarize, write_log, write_outputs
from .shards import RESULTS, ShardError, check_shards, merged_records, read_shard

__all__ = ["merge", "shard_rows", "shards_markdown"]


def _merged_before(folder: str) -> bool:
    """Whether `folder` holds nothing, or only an earlier merge (which a new one replaces)."""
    log = os.path.join(folder, LOG)
    if not os.path.exists(log) or os.path.getsize(log) == 0:
        return True
    try:
        with open(os.path.join(folder, RESULTS), encoding="utf-8") as f:
            return "merged_from" in json.load(f).get("run", {})
    except (OSError, ValueError, AttributeError):
        return False


def shard_rows(runs: Sequence[Any]) -> list[dict[str, Any]]:
    """Each shard's time, host and episodes, in shard order."""
    rows = []
    for r in sorted(runs, key=lambda r: r.shard.index):
        run = r.results.get("run", {})
        rows.append(
            {
                "shard": str(r.shard),
                "folder": os.path.abspath(r.folder),
                "host": run.get("host"),
                "started": run.get("started"),
                "finished": run.get("finished"),
                "seconds": run.get("seconds"),
                "episodes": len(r.records),
                "env_steps": run.get("env_steps"),
                "num_envs": run.get("num_envs"),
                "attempts": run.get("attempts", 1),
            }
        )
    return rows


def merge(out: str | os.PathLike[str], folders: Sequence[str | os.PathLike[str]], report: bool = False) -> dict[str, Any]:
    """Joins the shard folders `folders` (every shard of one evaluation, each once, finished)
    into `out`; returns the results dict, equal to the one-machine run's but for `run`."""
    out = os.fspath(out)
    folders = [os.fspath(f) for f in folders]
    for f in folders:
        if os.path.abspath(f) == os.path.abspath(out):
            raise ShardError(f"the merged folder {out} is one of the shards: give another OUT")
    runs = [read_shard(f) for f in folders]
    check_shards(runs)
    first = runs[0]
    header = {k: v for k, v in first.header.items() if k != "shard"}
    protocol = header["protocol"]
    keys = [f"{t}#{k}" for t in header["tasks"] for k in range(int(protocol["episodes_per_task"]))]
    records = merged_records(runs, keys)
    lock = FolderLock(out)  # creates `out`; refuses while another evaluation writes into it
    try:
        if not _merged_before(out):
            raise ShardError(f"{out} already holds an evaluation: merge into a new folder (or an earlier merge's)")
        for rec in records:
            if rec.get("video"):
                rec["video"] = os.path.relpath(rec["video"], os.path.abspath(out)).replace(os.sep, "/")
        task_plan = first.results["tasks"]
        rule = protocol["success"]["rule"]
        summary, per_task = summarize(records, task_plan, rule, len(keys))
        shards = shard_rows(runs)
        started = min((s["started"] for s in shards if s["started"]), default=None)
        finished = max((s["finished"] for s in shards if s["finished"]), default=None)
        seconds = _span(started, finished)
        summary["episodes_per_minute"] = len(records) / seconds * 60 if seconds else None
        results = {
            "schema": first.results.get("schema", "envhub.eval/1"),
            "benchmark": header["benchmark"],
            "description": first.results.get("description"),
            "protocol": protocol,
            "tasks": task_plan,
            "policy": header["policy"],
            "versions": first.results.get("versions"),
            "run": {
                "started": started,
                "finished": finished,
                "seconds": seconds,
                "num_envs": sum(s["num_envs"] or 0 for s in shards),
                "workers": first.results.get("run", {}).get("workers"),
                "hubs": first.results.get("run", {}).get("hubs"),
                "resumed": any(r.results.get("run", {}).get("resumed") for r in runs),
                "host": sorted({s["host"] for s in shards if s["host"]}),
                "env_steps": sum(s["env_steps"] or 0 for s in shards),
                "out": os.path.abspath(out),
                "dataset": None,
                "merged_from": [s["folder"] for s in shards],
                "shards": shards,
            },
            "summary": summary,
            "per_task": per_task,
            **axis_rows(task_plan, records, rule),
            "episodes": records,
        }
        _write_json(os.path.join(out, RUN), header)
        write_log(os.path.join(out, LOG), records)
        write_outputs(out, results, report)
        return results
    finally:
        lock.release()


def shards_markdown(results: dict[str, Any]) -> str:
    """Each shard's host, episodes, attempts and time, as markdown."""
    lines = ["| shard | host | episodes | attempts | seconds | episodes/min |", "|---|---|---:|---:|---:|---:|"]
    for s in results["run"].get("shards") or []:
        secs = s.get("seconds")
        rate = f"{s['episodes'] / secs * 60:.1f}" if secs else "–"
        lines.append(f"| {s['shard']} | {s.get('host') or '?'} | {s['episodes']} | {s.get('attempts', 1)} | "
                     f"{'–' if secs is None else f'{secs:.1f}'} | {rate} |")
    return "\n".join(lines) + "\n"


def _span(started: str | None, finished: str | None) -> float | None:
    """Seconds from the first shard's start to the last one's end (ISO 8601 UTC times)."""
    import datetime

    if not started or not finished:
        return None
    a = datetime.datetime.fromisoformat(started.replace("Z", "+00:00"))
    b = datetime.datetime.fromisoformat(finished.replace("Z", "+00:00"))
    return max((b - a).total_seconds(), 0.0)
