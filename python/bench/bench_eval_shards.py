"""An evaluation past one process: `envhub eval --ray --shards K` on a local Ray cluster of K
CPUs (K Ray workers, one shard each) against one `envhub eval` process, same episodes, as
episodes per minute, in alternated rounds.

    python python/bench/bench_eval_shards.py [--workers 1 2 4] [--episodes 3] [--rounds 2]

The benchmark is Meta-World MT10 with its scripted experts (`--episodes` per task, the
policy in the catalog's `metaworld` environment, one env per shard); the one-process
baseline runs the same episodes with `--num-envs 1` and with `--num-envs K`. Each Ray run
starts its cluster before the clock starts (`ray start --head --num-cpus K`) and stops it
after; a shard's start (its hub, the suite's workers, the policy's interpreter) is inside the
clock, as it is for the baseline. Prints one JSON line per run and the medians with their
ratio to the one-process run; every run's table must equal the baseline's (checked).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import secrets
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time

RAY = os.path.join(os.path.dirname(sys.executable), "ray")
# The clusters and the drivers share a token of their own (Ray's token authentication).
RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}


def rows(folder: str) -> list[dict]:
    with open(os.path.join(folder, "results.csv"), newline="") as f:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(f)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def evaluate(args: list[str], out: str) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "envhub.evaluation", *args, "--out", out, "--quiet"],
                          capture_output=True, text=True, timeout=3600, env={**os.environ, **RAY_ENV})
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"envhub eval {' '.join(args)} failed: {done.stderr[-3000:]}")
    return seconds


def with_cluster(cpus: int, run):
    temp = tempfile.mkdtemp(prefix="ray-", dir="/tmp")
    port = free_port()
    env = {**os.environ, **RAY_ENV}
    subprocess.run([RAY, "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", f"--num-cpus={cpus}",
                    "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp}",
                    "--object-store-memory=100000000", f"--ray-client-server-port={free_port()}"],
                   check=True, capture_output=True, env=env, timeout=300)
    try:
        return run(f"127.0.0.1:{port}")
    finally:
        subprocess.run([RAY, "stop", "--force"], capture_output=True, env=env, timeout=120)
        shutil.rmtree(temp, ignore_errors=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--rounds", type=int, default=2)
    a = p.parse_args()
    base = ["metaworld-mt10", "--policy", "envhub.evaluation.experts:metaworld", "--policy-env", "metaworld",
            "--episodes", str(a.episodes)]
    episodes = 10 * a.episodes
    root = tempfile.mkdtemp(prefix="envhub-bench-shards-")
    times: dict[str, list[float]] = {}
    reference = None
    try:
        for r in range(a.rounds):
            runs = [("one process, 1 env", 1, None)] + [(f"one process, {k} envs", k, None) for k in a.workers if k > 1]
            runs += [(f"ray, {k} workers", 1, k) for k in a.workers]
            for name, envs, workers in runs:
                out = os.path.join(root, f"{r}-{name.replace(' ', '').replace(',', '-')}")
                args = [*base, "--num-envs", str(envs)]
                if workers is None:
                    seconds = evaluate(args, out)
                else:
                    seconds = with_cluster(workers, lambda addr, args=args, out=out, k=workers: evaluate(
                        [*args, "--ray", addr, "--shards", str(k)], out))
                table = rows(out)
                if reference is None:
                    reference = table
                elif table != reference:
                    raise SystemExit(f"{name}: its table differs from the first run's")
                times.setdefault(name, []).append(seconds)
                print(json.dumps({"round": r, "run": name, "seconds": round(seconds, 2),
                                  "episodes_per_minute": round(episodes / seconds * 60, 2)}), flush=True)
        one = statistics.median(times["one process, 1 env"])
        for name, ts in times.items():
            med = statistics.median(ts)
            print(json.dumps({"run": name, "median_episodes_per_minute": round(episodes / med * 60, 2),
                              "over_one_process": round(one / med, 2), "cores": os.cpu_count()}))
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
