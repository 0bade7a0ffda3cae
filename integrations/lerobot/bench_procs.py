"""CPU seconds and memory of a process and its descendants, read from /proc while it runs,
for bench_eval.py: what each role in a `lerobot-eval` run (the evaluating process, envhub's
hub and workers, `AsyncVectorEnv`'s env processes) costs the machine."""

from __future__ import annotations

import os
import threading
from pathlib import Path

TICK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def stat(pid: int) -> tuple[int, float, str] | None:
    """(parent pid, CPU seconds user + system, command line) of a live process."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return None
    fields = raw[raw.rindex(")") + 2 :].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / TICK, cmdline.strip()


def rss(pid: int) -> int:
    try:
        return int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * PAGE
    except OSError:
        return 0


def role(pid: int, root: int, cmdline: str) -> str:
    """Which part of a `lerobot-eval` run a process is: the evaluating process itself, the
    env processes (envhub's workers, or `AsyncVectorEnv`'s, forked by multiprocessing's
    forkserver), envhub's hub, py-spy, or other (multiprocessing's resource tracker)."""
    if "py-spy" in cmdline:
        return "profiler"
    if pid == root or "lerobot.scripts.lerobot_eval" in cmdline:
        return "lerobot-eval"
    if "resource_tracker" in cmdline:
        return "other"
    if cmdline.split(" ", 1)[0].endswith("/envhub"):
        return "envhub hub"
    return "env processes"


def program(cmdline: str) -> str:
    """A command line's program and its first argument, shortened (`python -m X`, a binary)."""
    words = cmdline.split()
    return " ".join(w.rsplit("/", 1)[-1][:60] for w in words[:3])


class Tree(threading.Thread):
    """Samples the tree under `root` every `period` seconds until `stop()`."""

    def __init__(self, root: int, period: float = 0.5) -> None:
        super().__init__(daemon=True)
        self.root, self.period = root, period
        self.cpu: dict[int, tuple[str, float, str]] = {}  # pid -> (role, CPU s, command line)
        self.peak_rss = 0
        self.peak_procs = 0
        self._done = threading.Event()

    def sample(self) -> None:
        parents: dict[int, int] = {}
        seen: dict[int, tuple[float, str]] = {}
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                got = stat(int(entry))
                if got is not None:
                    parents[int(entry)] = got[0]
                    seen[int(entry)] = got[1:]
        tree, grown = {self.root}, True
        while grown:
            more = {pid for pid, parent in parents.items() if parent in tree} - tree
            tree |= more
            grown = bool(more)
        tree &= set(seen)
        for pid in tree:
            cpu, cmdline = seen[pid]
            if pid in self.cpu and not cmdline:  # exited, not yet reaped: keep what it was
                self.cpu[pid] = (self.cpu[pid][0], cpu, self.cpu[pid][2])
            else:
                self.cpu[pid] = (role(pid, self.root, cmdline), cpu, cmdline)
        self.peak_rss = max(self.peak_rss, sum(rss(pid) for pid in tree))
        self.peak_procs = max(self.peak_procs, len(tree))

    def run(self) -> None:
        while not self._done.wait(self.period):
            self.sample()

    def stop(self) -> dict:
        self._done.set()
        self.join()
        by_role: dict[str, float] = {}
        procs: dict[str, int] = {}
        for name, cpu, _ in self.cpu.values():
            by_role[name] = by_role.get(name, 0.0) + cpu
            procs[name] = procs.get(name, 0) + 1
        programs = sorted({f"{name}: {program(cmdline)}" for name, _, cmdline in self.cpu.values()})
        return {
            "cpu_s": {k: round(v, 1) for k, v in sorted(by_role.items())},
            "processes": dict(sorted(procs.items())),
            "programs": programs,
            "peak_rss_gb": round(self.peak_rss / 2**30, 2),
        }
