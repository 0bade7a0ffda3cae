"""Episode results, durable as they come: one JSON line per episode appended to
`episodes.jsonl` and fsynced, so a killed evaluation resumes (`--resume`) with no episode
lost or counted twice; then `results.json` (schema in docs/guide/eval.md), `results.csv` and a
markdown table."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from typing import Any

from .stats import wilson

__all__ = ["EpisodeLog", "FolderLock", "FolderLocked", "ResumeError", "Progress", "summarize", "markdown", "write_outputs"]

SCHEMA = "envhub.eval/1"
LOG = "episodes.jsonl"
RUN = "run.json"
LOCK = ".lock"


class ResumeError(ValueError):
    """`--resume` on a folder that holds another evaluation."""


class FolderLocked(FileExistsError):
    """The output folder belongs to an evaluation that is running."""


class FolderLock:
    """One evaluation per output folder: an exclusive `flock` on `<folder>/.lock`, which holds
    the owner's pid, kept until `release` (the kernel drops it when the process ends, however
    it ends: a killed run leaves no stale lock)."""

    def __init__(self, folder: str) -> None:
        import fcntl

        os.makedirs(folder, exist_ok=True)
        self.path = os.path.join(folder, LOCK)
        self.fd: int | None = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = os.pread(self.fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(self.fd)
            self.fd = None
            raise FolderLocked(
                f"{folder} is in use by a running evaluation (pid {owner})\n"
                "hint: wait for it to end (or stop it), then --resume; or use another --out"
            ) from None
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # the flock goes with the last descriptor
            self.fd = None


class EpisodeLog:
    """`episodes.jsonl` in the output folder, with the protocol it was written under
    (`run.json`): resuming under another protocol is refused."""

    def __init__(self, folder: str, header: dict[str, Any], resume: bool) -> None:
        os.makedirs(folder, exist_ok=True)
        self.path = os.path.join(folder, LOG)
        run = os.path.join(folder, RUN)
        self.records: dict[str, dict[str, Any]] = {}
        if resume and os.path.exists(run):
            with open(run, encoding="utf-8") as f:
                before = json.load(f)
            if before != header:
                changed = sorted(k for k in set(before) | set(header) if before.get(k) != header.get(k))
                raise ResumeError(
                    f"--resume: {folder} holds an evaluation of another protocol (differs in {', '.join(changed)})\n"
                    "hint: resume with the same benchmark, tasks, episodes and policy, or use another --out"
                )
            self.records = read_log(self.path)
            _drop_torn_tail(self.path)
        elif not resume and os.path.exists(self.path) and os.path.getsize(self.path):
            raise FileExistsError(f"{folder} already holds an evaluation\nhint: --resume to go on with it, or another --out")
        _write_json(run, header)
        if not resume and os.path.exists(self.path):
            os.remove(self.path)
        self._file = open(self.path, "a", encoding="utf-8")

    def done(self) -> set[str]:
        """Episodes finished without an error (an errored one runs again on resume)."""
        return {k for k, r in self.records.items() if r.get("error") is None}

    def add(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, allow_nan=False) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())
        self.records[f"{record['task']}#{record['index']}"] = record

    def close(self) -> None:
        self._file.close()


def read_log(path: str) -> dict[str, dict[str, Any]]:
    """The last record of each episode in a log; a torn last line (a kill mid-write) is skipped."""
    out: dict[str, dict[str, Any]] = {}
    if not os.path.exists(path):
        return out
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                continue
            out[f"{r['task']}#{r['index']}"] = r
    return out


def _drop_torn_tail(path: str) -> None:
    """Cuts a last line a kill left half-written, so the next record starts a line."""
    if not os.path.exists(path):
        return
    with open(path, "rb+") as f:
        data = f.read()
        if data and not data.endswith(b"\n"):
            f.truncate(data.rfind(b"\n") + 1)


def write_log(path: str, records: Any) -> None:
    """`records` as a whole new episode log at `path`, replacing it at once (fsynced first)."""
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.writelines(json.dumps(r, allow_nan=False) + "\n" for r in records)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _write_json(path: str, data: Any) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1, allow_nan=False)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _rate(records: list[dict[str, Any]], rule: str) -> dict[str, Any]:
    n = len(records)
    errors = sum(1 for r in records if r.get("error") is not None)
    successes = sum(1 for r in records if r.get("success"))
    returns = [r["return"] for r in records if r.get("return") is not None]
    lengths = [r["length"] for r in records if r.get("length") is not None]
    out: dict[str, Any] = {"episodes": n, "successes": successes, "errors": errors}
    if rule == "none" or n == 0:
        out["success_rate"] = out["stderr"] = out["ci95"] = None
    else:
        p = successes / n  # an errored episode counts as a failure
        out["success_rate"] = p
        out["stderr"] = math.sqrt(p * (1 - p) / n)
        out["ci95"] = list(wilson(successes, n))  # type: ignore[arg-type]
    out["mean_return"] = sum(returns) / len(returns) if returns else None
    out["mean_length"] = sum(lengths) / len(lengths) if lengths else None
    return out


def summarize(records: list[dict[str, Any]], tasks: list[dict[str, Any]], rule: str, total: int) -> tuple[dict, list]:
    """(overall, per task) success rates with standard errors, returns and lengths."""
    overall = _rate(records, rule)
    overall["done"] = len(records)
    overall["episodes"] = total
    per_task = []
    for t in tasks:
        mine = [r for r in records if r["task"] == t["id"]]
        per_task.append({"task": t["id"], "text": t["text"], **_rate(mine, rule)})
    return overall, per_task


def markdown(results: dict[str, Any]) -> str:
    """The per-task table and the overall line, as markdown."""
    rule = results["protocol"]["success"]["rule"]
    lines = [f"### {results['benchmark']}: {results['policy'].get('name', results['policy'].get('kind', ''))}", ""]
    if rule == "none":
        lines += ["| task | episodes | errors | mean return | mean length |", "|---|---:|---:|---:|---:|"]
    else:
        lines += [
            "| task | episodes | success | 95% CI (Wilson) | ± s.e. | errors | mean return |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]

    def num(x: Any, fmt: str) -> str:
        return "–" if x is None else format(x, fmt)

    def interval(ci: Any) -> str:
        return "–" if ci is None else f"{ci[0]:.3f}–{ci[1]:.3f}"

    rows = results["per_task"] + [{"task": "**all**", **results["summary"]}]
    for r in rows:
        if rule == "none":
            lines.append(
                f"| {r['task']} | {r['episodes']} | {r['errors']} | {num(r['mean_return'], '.3f')} | {num(r['mean_length'], '.1f')} |"
            )
        else:
            lines.append(
                f"| {r['task']} | {r['episodes']} | {num(r['success_rate'], '.3f')} | {interval(r.get('ci95'))} "
                f"| {num(r['stderr'], '.3f')} | {r['errors']} | {num(r['mean_return'], '.3f')} |"
            )
    from .axes import rows as axis_rows

    by_axis = axis_rows(results)
    if by_axis:  # a perturbation benchmark: the same figures per axis, and each axis against `original`
        lines += ["", "| axis | tasks | episodes | success | 95% CI (Wilson) | ± s.e. | vs original | errors |"]
        lines.append("|---|---:|---:|---:|---:|---:|---:|---:|")
        for r in by_axis:
            delta = r.get("vs_original")
            lines.append(
                f"| {r['axis']} | {r['tasks']} | {r['episodes']} | {num(r['success_rate'], '.3f')} | {interval(r.get('ci95'))} "
                f"| {num(r['stderr'], '.3f')} | {'–' if delta is None else format(delta, '+.3f')} | {r['errors']} |"
            )
    return "\n".join(lines) + "\n"


CSV_FIELDS = ["task", "index", "init", "success", "return", "length", "seconds", "error", "video"]
TASK_FIELDS = [
    "task", "episodes", "successes", "errors", "success_rate", "ci95_low", "ci95_high", "stderr", "mean_return", "mean_length",
]


def write_outputs(folder: str, results: dict[str, Any], report: bool = False) -> None:
    """`results.json`, `results.csv` (one row per episode) and `tasks.csv` (one row per task
and one for all: success rates with their Wilson 95 % intervals) in `folder`; `report.html`
too with `report`."""
    _write_json(os.path.join(folder, "results.json"), results)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS)
    w.writeheader()
    for e in results["episodes"]:
        w.writerow({**{k: e.get(k) for k in CSV_FIELDS}, "init": json.dumps(e.get("init"))})
    with open(os.path.join(folder, "results.csv"), "w", encoding="utf-8", newline="") as f:
        f.write(buf.getvalue())
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TASK_FIELDS)
    w.writeheader()
    for r in results["per_task"] + [{"task": "all", **results["summary"]}]:
        ci = r.get("ci95") or [None, None]
        w.writerow({**{k: r.get(k) for k in TASK_FIELDS}, "ci95_low": ci[0], "ci95_high": ci[1]})
    with open(os.path.join(folder, "tasks.csv"), "w", encoding="utf-8", newline="") as f:
        f.write(buf.getvalue())
    if report:
        from .report import write_report

        write_report(results, os.path.join(folder, "report.html"))


class Progress:
    """One line on stderr as episodes finish: done/total, success so far, episodes per
    minute, ETA (rewritten in place on a terminal, a new line at most every few seconds
    otherwise)."""

    def __init__(self, total: int, already: int, rule: str, stream: Any = None, quiet: bool = False) -> None:
        self.total, self.already, self.rule = total, already, rule
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.quiet = quiet
        self.t0 = time.monotonic()
        self.last = 0.0
        self.done = self.successes = 0
        self.errors_seen: set[str] = set()

    def episode(self, success: bool | None) -> None:
        self.done += 1
        self.successes += bool(success)
        now = time.monotonic()
        if self.quiet or (not self.tty and now - self.last < 5 and self.already + self.done < self.total):
            return
        self.last = now
        elapsed = max(now - self.t0, 1e-9)
        per_min = self.done / elapsed * 60
        left = self.total - self.already - self.done
        eta = left / (self.done / elapsed) if self.done else float("inf")
        rate = "" if self.rule == "none" else f" success {self.successes / self.done:.3f}"
        line = (
            f"[{self.already + self.done}/{self.total}]{rate} | {per_min:.1f} episodes/min | "
            f"ETA {_duration(eta)}"
        )
        self.stream.write(("\r" + line + "\x1b[K") if self.tty else line + "\n")
        self.stream.flush()

    def error(self, episode: str, message: str) -> None:
        """An episode's error, on stderr whatever `quiet` says: in full the first time a
        message is seen, then its first line (a broken policy fails many episodes alike)."""
        first = message.splitlines()[0] if message else ""
        text = message if first not in self.errors_seen else f"{first} (as above)"
        self.errors_seen.add(first)
        lead = "\r\x1b[K" if self.tty and not self.quiet else ""
        self.stream.write(f"{lead}episode {episode} failed: {text}\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty and not self.quiet:
            self.stream.write("\n")


def _duration(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = int(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"
