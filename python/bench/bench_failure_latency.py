"""How fast failures reach a Python client: the figures the tests used to bound and no longer
do (a test asserts what the error says, never how soon it came; issue 44).

- `killed idle`: a worker killed with SIGKILL between steps, until the next step raises
  `WorkerDiedError` (the hub's watch on the process sees its exit);
- `killed mid-step`: a worker killed while a step waits on it (an env that sleeps), from the
  kill to the raise;
- `timeout overshoot`: a step that would sleep ten minutes with `step_timeout=0.5`, how long
  past the 0.5 s the `WorkerDiedError` came;
- `ctrl-c`: SIGINT to a client process whose step waits on its workers, until its
  `KeyboardInterrupt` handler runs (the client prints the time; one clock, one machine).

    .venv/bin/python python/bench/bench_failure_latency.py [--repeat 5] [--json]

Each figure is the median and the worst of `--repeat` tries, in milliseconds. On a loaded
machine the worst grows first: that is why no test bounds these.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path

# The `null` test adapter (an env that sleeps on request) is listed only with this set.
os.environ["ENVHUB_TEST_ADAPTERS"] = "1"
os.environ.setdefault("ENVHUB_NAMESPACE", f"benchfail{os.getpid()}_")

import envhub

NULL_REGISTRY = """\
environments:
  - id: null-env
    name: Null
    framework: envhub
    env_id: Null-v0
    robot_type: custom
    env_type: floor
    task_tags: [nothing]
    description: Does no work.
"""

CLIENT = textwrap.dedent(
    """\
    import signal, sys, time
    import numpy as np
    import envhub

    signal.signal(signal.SIGINT, signal.default_int_handler)
    envs = envhub.make_vec("null-env", 2, num_workers=2, registry=sys.argv[1], sleep_ms=600_000, step_timeout=1200)
    envs.reset(seed=0)
    print("ready", flush=True)
    try:
        envs.step(np.zeros(2, dtype=np.int64))
    except KeyboardInterrupt:
        print("interrupted", time.monotonic(), flush=True)
    """
)


def killed_idle(registry: str) -> float:
    env = envhub.make("gym-cartpole", step_timeout=60.0)
    try:
        env.reset(seed=0)
        os.kill(env.worker_pid, signal.SIGKILL)
        start = time.monotonic()
        try:
            env.step(0)
        except envhub.WorkerDiedError:
            return time.monotonic() - start
        raise AssertionError("a step after the kill succeeded")
    finally:
        env.close()


def killed_mid_step(registry: str) -> float:
    env = envhub.make("null-env", registry=registry, sleep_ms=600_000, step_timeout=60.0)
    try:
        env.reset(seed=0)
        killed_at: list[float] = []

        def kill() -> None:
            killed_at.append(time.monotonic())
            os.kill(env.worker_pid, signal.SIGKILL)

        threading.Timer(0.3, kill).start()
        try:
            env.step(0)
        except envhub.WorkerDiedError:
            return time.monotonic() - killed_at[0]
        raise AssertionError("the step outlived its worker")
    finally:
        env.close()


def timeout_overshoot(registry: str) -> float:
    env = envhub.make("null-env", registry=registry, sleep_ms=600_000, step_timeout=0.5)
    try:
        env.reset(seed=0)
        start = time.monotonic()
        try:
            env.step(0)
        except envhub.WorkerDiedError:
            return time.monotonic() - start - 0.5
        raise AssertionError("the step did not time out")
    finally:
        env.close()


def ctrl_c(registry: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "client.py"
        script.write_text(CLIENT)
        child = subprocess.Popen(
            [sys.executable, str(script), registry], stdout=subprocess.PIPE, text=True, start_new_session=True
        )
        try:
            assert child.stdout is not None and child.stdout.readline().startswith("ready")
            time.sleep(0.3)  # the step is under way
            sent = time.monotonic()
            child.send_signal(signal.SIGINT)
            out, _ = child.communicate(timeout=120)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        words = out.split()
        assert words and words[0] == "interrupted", out
        return float(words[1]) - sent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    args = parser.parse_args()
    cases: dict[str, Callable[[str], float]] = {
        "killed idle": killed_idle,
        "killed mid-step": killed_mid_step,
        "timeout overshoot": timeout_overshoot,
        "ctrl-c": ctrl_c,
    }
    with tempfile.TemporaryDirectory() as tmp:
        registry = str(Path(tmp) / "null_registry.yaml")
        Path(registry).write_text(NULL_REGISTRY)
        figures = {}
        for name, case in cases.items():
            ms = [case(registry) * 1000 for _ in range(args.repeat)]
            figures[name] = {"median_ms": round(statistics.median(ms), 2), "max_ms": round(max(ms), 2)}
    if args.json:
        print(json.dumps({"cpus": os.cpu_count(), "load1": os.getloadavg()[0], "figures": figures}))
        return
    print(f"{'case':<20}{'median ms':>12}{'worst ms':>12}   ({os.cpu_count()} cpus, load {os.getloadavg()[0]:.1f})")
    for name, f in figures.items():
        print(f"{name:<20}{f['median_ms']:>12.2f}{f['max_ms']:>12.2f}")


if __name__ == "__main__":
    main()
