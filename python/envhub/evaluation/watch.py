"""`envhub eval status OUT [--follow]`: one progress line for an evaluation whose shards run
elsewhere (a Slurm job array, machines of their own) and write into `OUT/shards/shard-I`:
episodes done of the total, success so far, episodes per minute and the time left, from the
shards' own logs; then a line per shard (done, total, running or finished)."""

from __future__ import annotations

import glob
import json
import os
import sys
import time
from typing import Any

from .distribute import SHARDS_DIR
from .results import LOG, RUN, _duration, read_log
from .shards import RESULTS, Shard, ShardError

__all__ = ["status", "status_main"]


def _slice_size(header: dict[str, Any]) -> int:
    lo, hi = Shard(int(header["shard"]["index"]), int(header["shard"]["count"])).bounds(_episodes(header))
    return hi - lo


def _episodes(header: dict[str, Any]) -> int:
    """The episodes of the whole run a shard's header belongs to."""
    return len(header["tasks"]) * int(header["protocol"]["episodes_per_task"])


def status(out: str) -> dict[str, Any]:
    """Each shard's state under `out` and their sum."""
    folders = sorted(glob.glob(os.path.join(out, SHARDS_DIR, "shard-*")), key=lambda f: int(f.rsplit("-", 1)[-1])
                     if f.rsplit("-", 1)[-1].isdigit() else -1)
    if not folders:
        raise ShardError(f"{out} has no shard folders ({SHARDS_DIR}/shard-I): give the --out of a run with --shards N")
    rows, count, first_start = [], None, None
    for folder in folders:
        try:
            with open(os.path.join(folder, RUN), encoding="utf-8") as f:
                header = json.load(f)
        except (OSError, ValueError):
            rows.append({"folder": folder, "state": "not started", "done": 0, "total": None, "successes": 0})
            continue
        count = int(header["shard"]["count"])
        records = read_log(os.path.join(folder, LOG))
        started = os.path.getmtime(os.path.join(folder, RUN))
        first_start = started if first_start is None else min(first_start, started)
        rows.append({
            "folder": folder,
            "shard": f"{header['shard']['index']}/{count}",
            "state": "finished" if os.path.exists(os.path.join(folder, RESULTS)) and len(records) >= _slice_size(header)
            else "running",
            "done": len(records),
            "total": _slice_size(header),
            "successes": sum(1 for r in records.values() if r.get("success")),
            "errors": sum(1 for r in records.values() if r.get("error") is not None),
            "rule": header["protocol"]["success"]["rule"],
            "episodes": _episodes(header),
        })
    total = next((r["episodes"] for r in rows if r.get("episodes")), None)
    done = sum(r["done"] for r in rows)
    elapsed = time.time() - first_start if first_start is not None else 0.0
    return {
        "shards": rows,
        "count": count,
        "done": done,
        "total": total,
        "successes": sum(r["successes"] for r in rows),
        "episodes_per_minute": done / elapsed * 60 if elapsed > 0 and done else None,
        "finished": bool(rows) and all(r["state"] == "finished" for r in rows) and len(rows) == count,
        "rule": next((r["rule"] for r in rows if r.get("rule")), "none"),
    }


def line(s: dict[str, Any]) -> str:
    """`[done/total] success 0.812 | 41.3 episodes/min | ETA 3m10s | 4 shards: 3 running, 1 finished`."""
    rate = s["episodes_per_minute"]
    left = (s["total"] or 0) - s["done"]
    eta = _duration(left / rate * 60) if rate else "?"
    success = "" if s["rule"] == "none" or not s["done"] else f" success {s['successes'] / s['done']:.3f}"
    states: dict[str, int] = {}
    for r in s["shards"]:
        states[r["state"]] = states.get(r["state"], 0) + 1
    missing = (s["count"] or 0) - len(s["shards"])
    if missing > 0:
        states["not started"] = states.get("not started", 0) + missing
    summary = ", ".join(f"{n} {k}" for k, n in states.items())
    per_min = "?" if rate is None else f"{rate:.1f}"
    return f"[{s['done']}/{s['total'] or '?'}]{success} | {per_min} episodes/min | ETA {eta} | {s['count'] or '?'} shards: {summary}"


def status_main(argv: list[str]) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="envhub eval status",
                                description="One progress line for a run whose shards write into OUT/shards/shard-I.")
    p.add_argument("out", metavar="OUT", help="the run's --out folder")
    p.add_argument("--follow", action="store_true", help="a line every --every seconds until every shard has finished")
    p.add_argument("--every", type=float, default=10.0, metavar="S")
    p.add_argument("--json", action="store_true", help="each shard's state as JSON")
    args = p.parse_args(argv)
    try:
        while True:
            s = status(args.out)
            if args.json:
                print(json.dumps(s, indent=1))
            else:
                print(line(s), flush=True)
            if not args.follow or s["finished"]:
                break
            time.sleep(max(args.every, 0.5))
    except ShardError as e:
        print(f"envhub eval status: error: {e}", file=sys.stderr)
        return 2
    if not args.json and not args.follow:
        for r in s["shards"]:
            print(f"  {r.get('shard', os.path.basename(r['folder']))}: {r['done']}/{r['total'] or '?'} {r['state']}")
    return 0
