"""A warm start for a suite's workers: `python -m envhub.worker forkserver --adapter NAME`.

The hub starts one per suite environment (interpreter and variables) and adapter, the first
time a session needs a worker there, exactly as it starts a worker, and keeps it for its
later sessions. Each forked worker takes its own hold on the environment (`--hold`), as a
cold worker's start-up does; the server holds none. It imports the adapter's modules (its `requires`: `metaworld`, `robosuite`,
...) once, says so on stdout, then reads one request a line on stdin, `{"job": JOB,
"reply": FIFO}`, forks, and answers `{"pid": PID}` (or `{"error": ...}`) at once. The child
opens the hub's FIFO as its reply channel and serves the job as `python -m envhub.worker
serve` would, without importing the suite again. Children are reaped by the kernel
(SIGCHLD ignored): the hub watches them through pidfds, as it watches a daemon's workers.
It ends when the hub closes its stdin (the hub exits) or dies.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import time
from typing import Any

from .entry import refusal, serve
from .hosted import all_adapters


def _say(fd: int, message: dict[str, Any]) -> None:
    data = (json.dumps(message) + "\n").encode()
    while data:
        data = data[os.write(fd, data) :]


def _preload(adapter_name: str) -> list[str]:
    """Imports what the adapter needs; the modules imported (a module that fails to import is
    left to the worker, which reports it as a cold one would)."""
    found = [a for a, n, _ in all_adapters() if a is not None and n == adapter_name]
    done = []
    for module in list(getattr(found[0], "requires", []) if found else []):
        try:
            importlib.import_module(module)
            done.append(module)
        except Exception as e:  # the worker will say why, with the job's context
            print(f"envhub fork server: cannot preload `{module}`: {e}", file=sys.stderr)
    return done


def run(adapter_name: str, hold: str | None = None, removed: str = "") -> int:
    out = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    start = time.perf_counter()
    preloaded = _preload(adapter_name)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    _say(out, {"ready": preloaded, "pid": os.getpid(), "seconds": time.perf_counter() - start})
    stdin = os.fdopen(0, "rb", buffering=0)
    while True:
        line = stdin.readline()
        if not line:
            return 0
        try:
            request = json.loads(line)
            job, reply = str(request["job"]), str(request["reply"])
        except (ValueError, KeyError, TypeError) as e:
            _say(out, {"error": f"unreadable fork request: {e}"})
            continue
        pid = os.fork()
        if pid == 0:
            _child(out, job, reply, hold, removed)
        _say(out, {"pid": pid})


def _hold(fd: int, hold: str, removed: str) -> bool:
    """Holds the environment for this worker's life (a shared `flock` of its own, as a cold
    worker's start-up takes), or says on `fd` that it was removed."""
    import fcntl

    try:
        held = os.open(hold, os.O_RDONLY)
        fcntl.flock(held, fcntl.LOCK_SH)
        if not os.path.exists(hold):
            raise FileNotFoundError(2, "removed", hold)
    except OSError:
        _say(fd, {"error": removed})
        return False
    return True


def _child(out: int, job: str, reply: str, hold: str | None, removed: str) -> None:
    """The forked worker: serves `job`, its ready line to the FIFO `reply`; never returns."""
    code = 1
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        os.close(out)
        devnull = os.open(os.devnull, os.O_RDONLY)
        os.dup2(devnull, 0)
        os.close(devnull)
        fd = os.open(reply, os.O_WRONLY | os.O_CLOEXEC)
        if hold is not None and not _hold(fd, hold, removed):
            code = 0
            return
        code = serve(job, reply_fd=fd)
    except BaseException:
        import traceback

        traceback.print_exc()
    finally:
        sys.stderr.flush()
        os._exit(code)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m envhub.worker forkserver", description=__doc__)
    parser.add_argument("command", choices=["forkserver"])
    parser.add_argument("--adapter", required=True)
    parser.add_argument("--hold", help="a provisioned environment's file each worker holds (shared flock)")
    parser.add_argument("--removed", default="", help="what a worker says when the environment was removed")
    args = parser.parse_args(argv)
    refused = refusal(os.environ.get("ENVHUB_WORKER_PROTOCOL"))
    if refused is not None:
        print(json.dumps({"error": refused}), flush=True)
        return 0
    return run(args.adapter, args.hold, args.removed)
