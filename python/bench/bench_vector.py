"""Steps/s of envhub against Gymnasium's vector envs, EnvPool and PufferLib, side by side, in one run.

    .venv/bin/python python/bench/bench_vector.py [--seconds 2] [--envs 8 64] [--only gym-cartpole]

For each env (gym-cartpole; mujoco-ant when envhub's MuJoCo adapter is available) and each
env count it measures, with random actions (a pool of pre-drawn batches, so sampling is not
what is measured) and autoreset on:

- `envhub.make_vec` with one worker process and with the default (one per core),
- gymnasium `SyncVectorEnv` and `AsyncVectorEnv(shared_memory=True)` over Gymnasium's envs,
- EnvPool (`envpool.make_gymnasium`, one thread per core), when `envpool` is installed,
- PufferLib (`pufferlib.vector.make` over `pufferlib.emulation.GymnasiumPufferEnv(gymnasium.make(id))`),
  when `pufferlib` is importable: Serial; Multiprocessing synchronous (`step`: send the whole
  batch, recv it) with one worker and with one per core (as many as envhub's default); and
  Multiprocessing async with one worker per core (the same n envs, batch_size n/2: send one
  half's actions, recv whichever half is ready; its rate counts the n/2 env steps each recv
  returns). The PyPI package that provides `pufferlib` alongside gymnasium 1.4 / numpy 2 is
  `pufferlib-core`, not `pufferlib`: see README.md beside this file,

then the per-step latency of one env: `envhub.make` against `gymnasium.make` (both with
Gymnasium's default wrappers when made through `gymnasium.make`, and raw). Ratios are
envhub's best over each peer. Numbers depend on the machine: run it where you compare.
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np

warnings.filterwarnings("ignore")

import envhub  # noqa: E402

try:
    import envpool
except Exception as exc:
    envpool = None
    ENVPOOL_WHY = f"{type(exc).__name__}: {exc}"
else:
    ENVPOOL_WHY = ""

try:
    import pufferlib
    import pufferlib.emulation
    import pufferlib.vector
except Exception as exc:
    pufferlib = None
    PUFFERLIB_WHY = f"{type(exc).__name__}: {exc}"
else:
    PUFFERLIB_WHY = ""

ENVS = {
    # envhub id: Gymnasium/EnvPool id
    "gym-cartpole": "CartPole-v1",
    "mujoco-ant": "Ant-v5",
}
ACTION_POOL = 64
CORES = os.cpu_count() or 1


def actions_for(space: gymnasium.Space, seed: int = 0) -> list[Any]:
    space.seed(seed)
    return [space.sample() for _ in range(ACTION_POOL)]


def rate(step: Callable[[Any], Any], actions: list[Any], num_envs: int, seconds: float) -> float:
    """Env steps per second of `step` over about `seconds`."""
    for i in range(20):
        step(actions[i % ACTION_POOL])
    steps = 0
    start = time.perf_counter()
    deadline = start + seconds
    while True:
        for i in range(100):
            step(actions[i % ACTION_POOL])
        steps += 100
        now = time.perf_counter()
        if now >= deadline:
            return steps * num_envs / (now - start)


def vector_rate(envs: Any, seconds: float, num_envs: int) -> float:
    try:
        envs.reset(seed=0)
        return rate(envs.step, actions_for(envs.action_space), num_envs, seconds)
    finally:
        envs.close()


def envpool_rate(gym_id: str, num_envs: int, seconds: float) -> float:
    envs = envpool.make_gymnasium(gym_id, num_envs=num_envs, batch_size=num_envs, num_threads=CORES, seed=0)
    try:
        envs.reset()
        space = gymnasium.spaces.Box(envs.action_space.low, envs.action_space.high) if isinstance(
            envs.action_space, gymnasium.spaces.Box
        ) else envs.action_space
        batched = gymnasium.vector.utils.batch_space(space, num_envs)
        return rate(envs.step, actions_for(batched), num_envs, seconds)
    finally:
        envs.close()


def pufferlib_version() -> str:
    if pufferlib is None:
        return f"not usable: {PUFFERLIB_WHY}"
    from importlib import metadata

    for dist in ("pufferlib", "pufferlib-core"):
        try:
            return f"{metadata.version(dist)} ({dist})"
        except metadata.PackageNotFoundError:
            pass
    return str(getattr(pufferlib, "__version__", "?"))


def puffer_env(gym_id: str, buf: Any = None, seed: int = 0) -> Any:
    """A Gymnasium env (`gymnasium.make`, default wrappers, as the gymnasium columns) as a PufferLib env."""
    return pufferlib.emulation.GymnasiumPufferEnv(env_creator=gymnasium.make, env_args=[gym_id], buf=buf, seed=seed)


def pufferlib_rates(gym_id: str, num_envs: int, seconds: float, why: dict[str, str]) -> dict[str, float | None]:
    """PufferLib's Serial, Multiprocessing (sync) and Multiprocessing (async, half batches).

    A configuration PufferLib does not accept here is None, with the reason in `why`."""
    vector = pufferlib.vector
    creator = functools.partial(puffer_env, gym_id)
    workers = min(CORES, num_envs)
    rows: dict[str, float | None] = {}
    rows["PufferLib Serial"] = vector_rate(
        vector.make(creator, num_envs=num_envs, backend=vector.Serial), seconds, num_envs
    )
    # One worker, as envhub's first column: PufferLib's workers and its recv busy-poll, so with one worker
    # per core the main process has no core of its own (see README.md).
    if workers > 1:
        rows["PufferLib MP 1w sync"] = vector_rate(
            vector.make(creator, num_envs=num_envs, num_workers=1, batch_size=num_envs,
                        backend=vector.Multiprocessing),
            seconds,
            num_envs,
        )
    # overwork: PufferLib refuses more workers than physical cores; envhub's default counts logical ones.
    sync, async_ = f"PufferLib MP {workers}w sync", f"PufferLib MP {workers}w async"
    sync_ok = num_envs % workers == 0
    rows[sync] = vector_rate(
        vector.make(creator, num_envs=num_envs, num_workers=workers, batch_size=num_envs,
                    backend=vector.Multiprocessing, overwork=True),
        seconds,
        num_envs,
    ) if sync_ok else None
    if not sync_ok:
        why[sync] = f"{num_envs} envs do not divide among {workers} workers"
    # Async: each recv returns the first ready block of n/2 envs, whose workers then wait for the next send.
    batch = num_envs // 2
    if not (workers > 1 and sync_ok and num_envs % 2 == 0 and batch % (num_envs // workers) == 0):
        rows[async_] = None
        why[async_] = f"needs 2+ workers and n/2 envs to be whole workers' envs ({num_envs} envs, {workers} workers)"
    else:
        envs = vector.make(creator, num_envs=num_envs, num_workers=workers, batch_size=batch,
                           backend=vector.Multiprocessing, overwork=True)
        try:
            envs.reset(seed=0)

            def send_recv(actions: Any) -> None:
                envs.send(actions)
                envs.recv()

            rows[async_] = rate(send_recv, actions_for(envs.action_space), batch, seconds)
        finally:
            envs.close()
    return rows


def latency(env: Any, seconds: float) -> tuple[float, float]:
    """Median and 99th percentile of one `step` in µs (resets excluded)."""
    actions = actions_for(env.action_space)
    env.reset(seed=0)
    times = []
    deadline = time.perf_counter() + seconds
    i = 0
    clock = time.perf_counter_ns
    while time.perf_counter() < deadline:
        for _ in range(100):
            t0 = clock()
            _, _, terminated, truncated, _ = env.step(actions[i % ACTION_POOL])
            times.append(clock() - t0)
            i += 1
            if terminated or truncated:
                env.reset()
    env.close()
    times.sort()
    return statistics.median(times) / 1e3, times[int(len(times) * 0.99)] / 1e3


def fmt_rate(x: float | None) -> str:
    return f"{'-':>12}" if x is None else f"{x:>12,.0f}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=2.0, help="measuring time per configuration")
    parser.add_argument("--envs", type=int, nargs="+", default=[8, 64], help="env counts")
    parser.add_argument("--only", nargs="+", choices=list(ENVS), help="envhub ids to measure")
    args = parser.parse_args()
    # MuJoCo writes MUJOCO_LOG.TXT into the working directory on model warnings: not the repo.
    os.chdir(tempfile.gettempdir())

    available = {a["name"] for a in envhub.AdapterRegistry().list_all() if a["available"]}
    load = " ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    print(f"machine: {CORES} cores (load average {load}), Python {sys.version.split()[0]}, "
          f"gymnasium {gymnasium.__version__}, numpy {np.__version__}, envpool {getattr(envpool, '__version__', 'not usable: ' + ENVPOOL_WHY)}, "
          f"pufferlib {pufferlib_version()}")
    print(f"envhub {envhub.__version__}, worker {envhub.worker_binary()}, adapters: {', '.join(sorted(available))}")
    print()

    results: dict[tuple[str, int], dict[str, float | None]] = {}
    for hub_id, gym_id in ENVS.items():
        if args.only and hub_id not in args.only:
            continue
        if hub_id == "mujoco-ant" and "mujoco" not in available:
            print(f"{hub_id}: skipped, envhub's MuJoCo adapter is not available here\n")
            continue
        for n in args.envs:
            row: dict[str, float | None] = {}
            why: dict[str, str] = {}
            row["envhub 1 worker"] = vector_rate(envhub.make_vec(hub_id, n, num_workers=1), args.seconds, n)
            workers = min(CORES, n)
            if workers > 1:
                row[f"envhub {workers} workers"] = vector_rate(
                    envhub.make_vec(hub_id, n, num_workers=workers), args.seconds, n
                )
            row["gymnasium Sync"] = vector_rate(
                gymnasium.make_vec(gym_id, n, vectorization_mode="sync"), args.seconds, n
            )
            row["gymnasium Async(shm)"] = vector_rate(
                gymnasium.make_vec(gym_id, n, vectorization_mode="async", vector_kwargs={"shared_memory": True}),
                args.seconds,
                n,
            )
            row["EnvPool"] = envpool_rate(gym_id, n, args.seconds) if envpool is not None else None
            if envpool is None:
                why["EnvPool"] = f"not usable: {ENVPOOL_WHY}"
            if pufferlib is not None:
                row.update(pufferlib_rates(gym_id, n, args.seconds, why))
            else:
                row["PufferLib"] = None
                why["PufferLib"] = f"not usable: {PUFFERLIB_WHY}"
            results[(hub_id, n)] = row
            best = max(v for k, v in row.items() if k.startswith("envhub") and v is not None)
            print(f"{hub_id} ({gym_id}), {n} envs, random actions, env steps/s:")
            for name, value in row.items():
                ratio = "" if name.startswith("envhub") or not value else f"   envhub best / this = {best / value:6.2f}x"
                if value is None and name in why:
                    ratio = f"   ({why[name]})"
                print(f"  {name:<24}{fmt_rate(value)}{ratio}")
            print(flush=True)

    print(f"single env, one step (µs, median / p99), random actions, {args.seconds:.0f} s each:")
    for hub_id, gym_id in ENVS.items():
        if (args.only and hub_id not in args.only) or (hub_id == "mujoco-ant" and "mujoco" not in available):
            continue
        rows = {
            "envhub.make": latency(envhub.make(hub_id), args.seconds),
            "gymnasium.make('envhub/..')": latency(gymnasium.make(f"envhub/{hub_id}"), args.seconds),
            "gymnasium.make": latency(gymnasium.make(gym_id), args.seconds),
            "gymnasium.make(..).unwrapped": latency(gymnasium.make(gym_id).unwrapped, args.seconds),
        }
        plain = rows["gymnasium.make"][0]
        print(f"  {hub_id} ({gym_id}):")
        for name, (median, p99) in rows.items():
            print(f"    {name:<30}{median:8.1f} / {p99:8.1f}   ({median / plain:5.2f}x gymnasium.make)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
