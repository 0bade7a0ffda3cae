"""Whose code a `lerobot-eval` run's CPU samples are in, from py-spy's raw output
(`py-spy record --subprocesses --native --format raw`), for bench_eval.py.

Each sample is one stack of one thread; it goes to the innermost frame that names an owner:
the software renderer (Mesa, OpenGL/EGL), the simulator (MuJoCo, robosuite, LIBERO,
Meta-World), envhub (its package, its extension's Rust code and Zenoh, the LeRobot plugin),
the policy (torch and its OpenMP threads), LeRobot's own code (its rollout, processors, video writing), Gymnasium and
multiprocessing (`AsyncVectorEnv`'s pipes and pickling), or the rest (the interpreter, imports,
numpy called from none of these). A thread blocked in a receive, a poll, a condition
variable or a lock waits: those samples are counted apart (py-spy's own idle detection
misses native waits). Samples are also split by process: the `lerobot-eval`
process and the env processes (envhub's workers or `AsyncVectorEnv`'s)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

#: (owner, pattern), tried in order on each frame, innermost frame first.
OWNERS = [
    ("renderer", re.compile(r"libgallium|llvmpipe|mesa|swrast|libGL|libEGL|libOSMesa|libGLX|glapi|/OpenGL/|lp_rast|lp_setup")),
    ("simulator", re.compile(r"mujoco|robosuite/|/libero/|metaworld/|\bmj[rv]?_")),
    ("envhub", re.compile(r"(^|[/ (:])_?envhub[\w-]*[/.:]|lerobot_env_envhub|zenoh|tokio")),
    ("torch", re.compile(r"torch/|libtorch|libc10|libgomp")),
    ("lerobot", re.compile(r"lerobot/")),
    ("gymnasium and multiprocessing", re.compile(r"gymnasium/|multiprocessing/|cloudpickle|pickle\.py")),
]
#: Where envhub keeps its suites' Python environments: a path there is the suite's, not envhub's.
CACHE = re.compile(r"\.cache/envhub/[^/ ]*/[^/ ]*/")
#: The end of a raw record: a frame, then its sample count.
END = re.compile(r"\) \d+$")


#: A thread blocked in one of these (its innermost frames) waits: no owner's work.
WAITS = re.compile(
    r"^(recvfrom|recv|recvmsg|read|poll|__poll|epoll_wait|select|pselect6?|pthread_cond_wait|pthread_cond_timedwait"
    r"|sem_wait|sem_timedwait|nanosleep|clock_nanosleep|accept4?|waitpid|wait4|__futex\w*|futex\w*) \("
    r"|PyThread_acquire_lock_timed|Thread4join|time_sleep"
)


def waiting(stack: list[str]) -> bool:
    """Whether a thread is blocked: a blocking call innermost (below at most one libc frame
    py-spy cannot name), except a file read during an import, which is work."""
    inner = stack[-3:]
    if any("importlib._bootstrap" in f for f in inner):
        return False
    return any(WAITS.search(f) for f in inner)


def owner(stack: list[str]) -> str:
    if waiting(stack):
        return "waiting"
    for frame in reversed(stack):
        frame = CACHE.sub("", frame)
        for name, pattern in OWNERS:
            if pattern.search(frame):
                return name
    return "other"


def records(text: str):
    """(process kind, frames, count) per stack. Under --subprocesses a stack starts with its
    process and each of its parents, `process PID:"COMMAND LINE"`, and a command line may
    hold newlines, semicolons and quotes (envhub's workers run a `python -c` script): a record
    ends at a line ending in a frame and its count; its own frames follow the last quote."""
    pending: list[str] = []
    for line in text.splitlines():
        pending.append(line)
        if not END.search(line):
            continue
        record, pending = "\n".join(pending), []
        stack_text, _, count = record.rpartition(" ")
        kind = "all"
        if stack_text.startswith("process "):
            last = stack_text.rindex("process ")
            kind = "lerobot-eval" if "lerobot.scripts.lerobot_eval" in stack_text[last:] else "env processes"
            stack_text = stack_text[stack_text.rindex('"') + 1 :].lstrip(";")
        yield kind, [f for f in stack_text.split(";") if f], int(count)


def split(path: Path) -> dict:
    """Each owner's share of the samples that are not waits, over all processes and per kind
    of process (with the number of such samples, and of waits)."""
    counts: dict[str, dict[str, int]] = {"all": {}}
    for kind, frames, count in records(Path(path).read_text(errors="replace")):
        name = owner(frames)
        for key in {"all", kind}:
            counts.setdefault(key, {})
            counts[key][name] = counts[key].get(name, 0) + count
    result = {}
    for key, by_owner in counts.items():
        waits = by_owner.pop("waiting", 0)
        total = sum(by_owner.values())
        ranked = sorted(by_owner.items(), key=lambda kv: -kv[1])
        shares = {k: round(v / total, 3) for k, v in ranked} if total else {}
        result[key] = {"samples": total, "waiting_samples": waits, **shares}
    return result


def cpu_seconds(shares: dict, cpu_s: dict[str, float]) -> dict[str, float]:
    """Each owner's CPU seconds: each kind of process's CPU seconds (from /proc, bench_procs.py)
    shared out as its samples are (py-spy also samples threads that wait for a core, and a
    busier side has more of those)."""
    seconds: dict[str, float] = {}
    for kind in ("lerobot-eval", "env processes"):
        for name, share in shares.get(kind, {}).items():
            if name not in ("samples", "waiting_samples"):
                seconds[name] = seconds.get(name, 0.0) + share * cpu_s.get(kind, 0.0)
    total = sum(seconds.values())
    ranked = sorted(seconds.items(), key=lambda kv: -kv[1])
    return {"total": round(total, 1), **{k: [round(v, 1), round(v / total, 3)] for k, v in ranked}} if total else {}


if __name__ == "__main__":
    # profile_split.py SAMPLES.txt [LEROBOT_EVAL_CPU_S ENV_PROCESSES_CPU_S]
    shares = split(Path(sys.argv[1]))
    print(json.dumps(shares))
    if len(sys.argv) == 4:
        print(json.dumps(cpu_seconds(shares, {"lerobot-eval": float(sys.argv[2]), "env processes": float(sys.argv[3])})))
