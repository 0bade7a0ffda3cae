"""CPU cost per env step of the Python halves of a Python-hosted env's path, in one process,
so that a loaded machine's scheduling does not enter (issue 20): what the worker's Python adds
to the envs' `step` (`HostedBatch.step_into` over the drop-in's `DropInEnv`, one call per
batch: the actions copied once, each observation written into its row, each info packed
into its row of typed columns) and what the client's Python does with the batch's infos
(viewing the columns as Gymnasium's vector layout), against the batching `SyncVectorEnv`
does in-process. The Rust halves (the shared-memory hand-off) are not in these figures;
`bench_overhead.py` measures the whole.

    .venv/bin/python python/bench/bench_worker_parts.py [--env Hopper-v5 HalfCheetah-v5] [--steps 2000] [--rounds 5]

Each figure is the best of `--rounds` rounds, in µs per env step.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import gymnasium
import numpy as np
from envhub import AsyncVectorEnv
from envhub.client.column_reader import ColumnReader
from envhub.wire.info_schema import INFO_ROW_BYTES
from envhub.wire.spaces import from_gymnasium
from envhub.worker import HostedBatch, HostedEnv
from envhub.worker.hosted.env_fns import DropInEnv


class _Batch:
    _add_info = gymnasium.vector.VectorEnv._add_info

    def __init__(self, n: int) -> None:
        self.num_envs = n


def best_us(fn: Callable[[], None], count: int, rounds: int) -> float:
    out = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        fn()
        out = min(out, (time.perf_counter() - start) / count * 1e6)
    return out


def measure(env_id: str, args: argparse.Namespace) -> None:
    n = args.envs
    raws = [gymnasium.make(env_id) for _ in range(n)]
    raw = raws[0]
    raw.action_space.seed(0)
    action = raw.action_space.sample()
    obs_desc, act_desc = from_gymnasium(raw.observation_space), from_gymnasium(raw.action_space)
    batch = HostedBatch([HostedEnv(DropInEnv(e), obs_desc, act_desc) for e in raws], "next_step", INFO_ROW_BYTES)
    ob = int(np.prod(raw.observation_space.shape)) * raw.observation_space.dtype.itemsize
    acts = memoryview(np.ascontiguousarray(np.stack([action] * n)).tobytes())
    obs, rewards = memoryview(bytearray(n * ob)), memoryview(bytearray(8 * n))
    term, trunc, fmask = (memoryview(bytearray(n)) for _ in range(3))
    cols = memoryview(bytearray(n * INFO_ROW_BYTES))
    selected = [True] * n
    steps = max(1, args.steps // n)

    # Both reset at each episode's end (a fallen Hopper steps at another cost) and start
    # from the same states.
    def bare() -> None:
        for i, e in enumerate(raws):
            e.reset(seed=i)
        for _ in range(steps):
            for e in raws:
                if any(e.step(action)[2:4]):
                    e.reset()

    def worker() -> None:
        for i, e in enumerate(raws):
            e.reset(seed=i)
        for _ in range(steps):
            batch.step_into(selected, acts, obs, rewards, term, trunc, fmask, None, cols)

    # The client's infos: the columns the worker wrote, with the schemas it announced.
    for i, e in enumerate(raws):
        e.reset(seed=i)
    announced = []
    for _ in range(3):  # past the reset's schema
        section, _ = batch.step_into(selected, acts, obs, rewards, term, trunc, fmask, None, cols)
        announced += json.loads(section) if section else []
    client = AsyncVectorEnv.__new__(AsyncVectorEnv)
    client._columns = ColumnReader(INFO_ROW_BYTES)
    assert not client._columns.learn(announced)
    cols_np = np.frombuffer(cols, np.uint8).reshape(n, INFO_ROW_BYTES)
    info = raws[0].step(action)[4]

    def client_infos() -> None:
        for _ in range(steps):
            client._info(None, None, n, cols_np)

    def gymnasium_infos() -> None:
        b = _Batch(n)
        for _ in range(steps):
            merged: dict = {}
            for k in range(n):
                merged = b._add_info(merged, info, k)

    t_bare = t_worker = float("inf")
    for _ in range(args.rounds):  # in alternation
        t_bare = min(t_bare, best_us(bare, steps * n, 1))
        t_worker = min(t_worker, best_us(worker, steps * n, 1))
    t_client = best_us(client_infos, steps * n, args.rounds)
    t_sync = best_us(gymnasium_infos, steps * n, args.rounds)
    got = client._info(None, None, n, cols_np)
    assert list(got) == list(gymnasium_infos_once(info, n)), (list(got), list(info))
    print(
        json.dumps(
            {
                "env": env_id,
                "env_step_us": round(t_bare, 2),
                "worker_python_extra_us": round(t_worker - t_bare, 2),
                "client_infos_us_per_env": round(t_client, 2),
                "sync_vector_env_infos_us_per_env": round(t_sync, 2),
            }
        ),
        flush=True,
    )
    for e in raws:
        e.close()


def gymnasium_infos_once(info: dict, n: int) -> dict:
    merged: dict = {}
    b = _Batch(n)
    for k in range(n):
        merged = b._add_info(merged, info, k)
    return merged


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--env", nargs="+", default=["Hopper-v5", "HalfCheetah-v5"])
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--envs", type=int, default=8)
    args = p.parse_args()
    for env_id in args.env:
        measure(env_id, args)

if __name__ == "__main__":
    main()
