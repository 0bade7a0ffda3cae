"""`envhub eval ... --ray [ADDRESS] --shards N`: one shard per Ray task, merged at the end.

Ray places the tasks (one per shard, `--cpus-per-shard` CPUs each) on the cluster's nodes;
each task runs `python -m envhub.evaluation ... --shard I/N` on its node, with its own
embedded hub and the suite's Python environment there, into a folder of that node, and
streams each finished episode back (a Ray streaming generator). The driver keeps what
arrives in `OUT/shards/shard-I` (durably, as `envhub eval` does), shows one progress line for
the whole run, and merges the shards into `OUT` when all have ended.

A task lost mid-run (its worker process or its node gone) costs only its unfinished
episodes: the driver submits the shard again, with the episodes it already holds, and the
new task (placed wherever Ray has room) resumes after them (`--resume`). `--ray-retries`
bounds the attempts. A shard that fails as a usage error (exit status 2: an unknown policy
module on that node, say) stops the run.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Iterator, Sequence

from ..wire.cores import CPUS_VAR
from .distribute import shard_folders
from .results import LOG, RUN, FolderLock, Progress, _write_json, read_log, write_log
from .shards import RESULTS, Shard, ShardError

__all__ = ["run_on_ray", "RayUnavailable"]

POLL = 0.2  # seconds between looks at a shard's log on its node
CONNECT_TRIES = 3


class RayUnavailable(ShardError):
    """Ray is not installed (`pip install 'envhub[ray]'`) or its cluster cannot be reached."""


def _die_with_parent() -> None:
    # The shard's evaluation ends with the Ray worker that started it (a lost task leaves
    # no evaluation running on its node).
    import ctypes
    import signal

    ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def shard_task(
    argv: list[str], shard: str, header: dict[str, Any] | None, done: list[dict[str, Any]], cwd: str, cpus: float
) -> Iterator[Any]:
    """Runs on a Ray node: the shard's evaluation (in the driver's folder `cwd` where the node
    has it, so that relative paths in `argv` mean what they meant there; its workers default
    to the `cpus` Ray reserved for it, `ENVHUB_CPUS`, not to the node's cores), yielding ("started", host, pid),
    ("header", run.json), ("episode", record) as each is durable, ("end", exit status,
    results or None, the end of its stderr)."""
    import socket

    folder = tempfile.mkdtemp(prefix="envhub-eval-shard-")
    proc = errors = None
    try:
        log_path, run_path = os.path.join(folder, LOG), os.path.join(folder, RUN)
        if header is not None:  # a retry: the episodes already kept are not run again
            _write_json(run_path, header)
            write_log(log_path, done)
        pos = os.path.getsize(log_path) if header is not None else 0
        errors = open(os.path.join(folder, "stderr.log"), "w+", encoding="utf-8")
        command = [sys.executable, "-m", "envhub.evaluation", *argv, "--shard", shard, "--out", folder, "--resume", "--quiet"]
        proc = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=errors, preexec_fn=_die_with_parent,
            cwd=cwd if os.path.isdir(cwd) else None, env={**os.environ, CPUS_VAR: str(max(1, int(cpus)))},
        )
        yield ("started", socket.gethostname(), os.getpid())
        sent_header = header is not None
        partial = b""
        while True:
            ended = proc.poll() is not None
            if not sent_header and os.path.exists(run_path):
                try:
                    with open(run_path, encoding="utf-8") as f:
                        yield ("header", json.load(f))
                    sent_header = True
                except ValueError:
                    pass  # being replaced: read it next time
            if os.path.exists(log_path):
                with open(log_path, "rb") as f:
                    f.seek(pos)
                    chunk = f.read()
                pos += len(chunk)
                lines = (partial + chunk).split(b"\n")
                partial = lines.pop()
                for line in lines:
                    if line.strip():
                        yield ("episode", json.loads(line))
            if ended:
                break
            time.sleep(POLL)
        results = None
        if os.path.exists(os.path.join(folder, RESULTS)):
            with open(os.path.join(folder, RESULTS), encoding="utf-8") as f:
                results = json.load(f)
        errors.seek(0)
        yield ("end", proc.returncode, results, errors.read()[-4000:])
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        if errors is not None:
            errors.close()
        shutil.rmtree(folder, ignore_errors=True)


class _ShardState:
    def __init__(self, shard: Shard, folder: str, resume: bool) -> None:
        self.shard, self.folder = shard, folder
        os.makedirs(folder, exist_ok=True)
        self.lock = FolderLock(folder)
        self.header: dict[str, Any] | None = None
        self.records: dict[str, dict[str, Any]] = {}
        if resume and os.path.exists(os.path.join(folder, RUN)):
            with open(os.path.join(folder, RUN), encoding="utf-8") as f:
                self.header = json.load(f)
            self.records = {k: r for k, r in read_log(os.path.join(folder, LOG)).items() if r.get("error") is None}
        elif os.path.exists(os.path.join(folder, LOG)) and os.path.getsize(os.path.join(folder, LOG)):
            self.lock.release()
            raise ShardError(f"{folder} already holds a shard's episodes\nhint: --resume to go on with them, or another --out")
        self._rewrite()
        self.attempts = 0
        self.hosts: list[str] = []
        self.results: dict[str, Any] | None = None
        self.error: str | None = None

    def _rewrite(self) -> None:
        if self.header is not None:
            _write_json(os.path.join(self.folder, RUN), self.header)
        path = os.path.join(self.folder, LOG)
        write_log(path, self.records.values())
        self.log = open(path, "a", encoding="utf-8")

    def add(self, record: dict[str, Any]) -> None:
        self.log.write(json.dumps(record, allow_nan=False) + "\n")
        self.log.flush()
        os.fsync(self.log.fileno())
        self.records[f"{record['task']}#{record['index']}"] = record

    def finish(self, results: dict[str, Any]) -> None:
        results.setdefault("run", {})["attempts"] = self.attempts
        results["run"]["hosts"] = self.hosts
        _write_json(os.path.join(self.folder, RESULTS), results)
        self.results = results

    def close(self) -> None:
        self.log.close()
        self.lock.release()


def _connect(address: str | None) -> Any:
    try:
        import ray
    except ImportError:
        raise RayUnavailable(
            "--ray needs Ray: pip install 'envhub[ray]' (or `pip install ray`) here and on every node"
        ) from None
    if not ray.is_initialized():
        options: dict[str, Any] = {"logging_level": "WARNING", "log_to_driver": False, "include_dashboard": False}
        host = (address or "").rsplit(":", 1)[0].strip("[]")
        if host in ("127.0.0.1", "localhost", "::1"):
            # A cluster on loopback is this machine's: the driver is on its node there, not on
            # the address Ray would guess for it (the LAN's, where no raylet of it listens).
            options["_node_ip_address"] = "127.0.0.1"
        error: Exception | None = None
        for attempt in range(CONNECT_TRIES):  # a loaded head can miss one connection's deadline
            try:
                ray.init(address=address, **options)
                error = None
                break
            except (ConnectionError, ValueError, RuntimeError) as e:
                error = e
                ray.shutdown()
                time.sleep(2.0 * (attempt + 1))
        if error is not None:
            e = error
            raise RayUnavailable(
                f"--ray {address or ''}: cannot reach a Ray cluster ({CONNECT_TRIES} tries): {e}".replace("  ", " ")
                + "\nhint: give the head node's address (ray start --head prints it); a cluster with token authentication "
                "needs its token here too (RAY_AUTH_MODE=token with RAY_AUTH_TOKEN, or ~/.ray/auth_token)"
            ) from None
    return ray


def run_on_ray(
    argv: Sequence[str],
    out: str,
    shards: int,
    *,
    bench: Any,
    address: str | None = None,
    retries: int = 3,
    cpus_per_shard: float = 1.0,
    resume: bool = False,
    report: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Runs the evaluation `argv` (its own arguments: benchmark, policy, options) as `shards`
    Ray tasks and merges them into `out`; returns the merged results."""
    from .merge import merge

    if shards < 1:
        raise ShardError(f"--shards must be at least 1, not {shards}")
    if retries < 0:
        raise ShardError(f"--ray-retries must be 0 or more, not {retries}")
    if not cpus_per_shard >= 0:  # NaN too
        raise ShardError(f"--cpus-per-shard must be 0 or more, not {cpus_per_shard}")
    ray = _connect(address)
    states = [_ShardState(Shard(i, shards), f, resume) for i, f in enumerate(shard_folders(out, shards))]
    events: queue.Queue[tuple[int, int, Any]] = queue.Queue()
    task = ray.remote(shard_task).options(num_cpus=cpus_per_shard, max_retries=0, num_returns="streaming")

    def submit(i: int) -> None:
        s = states[i]
        s.attempts += 1
        gen = task.remote(list(argv), str(s.shard), s.header, list(s.records.values()), os.getcwd(), cpus_per_shard)
        attempt = s.attempts

        def drain() -> None:
            try:
                for ref in gen:
                    events.put((i, attempt, ray.get(ref)))
            except Exception as e:  # a lost worker or node: the shard runs again
                events.put((i, attempt, ("lost", f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")))

        threading.Thread(target=drain, name=f"envhub-ray-shard-{i}", daemon=True).start()

    slices = [set(s.shard.keys(bench)) for s in states]
    already = sum(len(s.records) for s in states)
    meter = Progress(sum(map(len, slices)), already, bench.rule, quiet=not progress)
    try:
        for i in range(shards):
            submit(i)
        running = set(range(shards))
        while running:
            i, attempt, event = events.get()
            s = states[i]
            if attempt != s.attempts:
                continue  # from an attempt given up on
            kind = event[0]
            if kind == "started":
                s.hosts.append(event[1])
            elif kind == "header":
                s.header = event[1]
                _write_json(os.path.join(s.folder, RUN), s.header)
            elif kind == "episode":
                record = event[1]
                key = f"{record['task']}#{record['index']}"
                if key in s.records and s.records[key].get("error") is None:
                    continue
                s.add(record)
                if record.get("error") is not None:
                    meter.error(key, str(record["error"]))
                meter.episode(record.get("success"))
            elif kind == "end":
                _, status, results, errors = event
                if status in (0, 1) and results is not None and slices[i] <= set(s.records):
                    s.finish(results)
                    running.discard(i)
                elif status == 2:
                    raise ShardError(f"shard {s.shard} refused its command on {s.hosts[-1] if s.hosts else '?'}: {errors.strip()}")
                else:
                    _retry(s, f"its evaluation exited with status {status}: {errors.strip()[-500:]}", retries, submit, meter)
            elif kind == "lost":
                _retry(s, event[1], retries, submit, meter)
        meter.close()
    finally:
        for s in states:
            s.close()
    return merge(out, [s.folder for s in states], report=report)


def _retry(s: _ShardState, why: str, retries: int, submit: Any, meter: Progress) -> None:
    if s.attempts > retries:
        raise ShardError(f"shard {s.shard} failed {s.attempts} times (last: {why}); its {len(s.records)} finished "
                         f"episodes are kept in {s.folder}: --resume goes on from them")
    meter.stream.write(f"shard {s.shard} lost ({why}); its unfinished episodes run again (attempt {s.attempts + 1} "
                       f"of {retries + 1}), its {len(s.records)} finished ones are kept\n")
    meter.stream.flush()
    submit(s.shard.index)
