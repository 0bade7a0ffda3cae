"""CPU cost per env step of the Python halves of a Python-hosted env's path, in one process,
so that a loaded machine's scheduling does not enter (issue 20): what the worker's Python adds
to an env's `step` (`HostedEnv.step_into` over the drop-in's `DropInEnv`: the action viewed
and copied, the observation written into its row, the info encoded as JSON) and what the
client's Python does with the batch's infos (decoding and batching them into Gymnasium's
vector layout), against the batching `SyncVectorEnv` does in-process. The Rust halves (the
info parsed and re-serialized in the worker and the client, the shared-memory hand-off) are
not in these figures; `bench_overhead.py` measures the whole.

    .venv/bin/python py-client/bench/bench_worker_parts.py [--env Hopper-v5 HalfCheetah-v5] [--steps 2000] [--rounds 5]

Each figure is the best of `--rounds` rounds, in µs per env step.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import gymnasium
import numpy as np
from envhub._pickled import decode_info
from envhub._spaces import from_gymnasium
from envhub.async_vector import AsyncVectorEnv
from envhub.hosted.env_fns import DropInEnv
from envhub.worker import HostedEnv


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
    raw = gymnasium.make(env_id)
    raw.reset(seed=0)
    raw.action_space.seed(0)
    action = raw.action_space.sample()
    hosted = HostedEnv(DropInEnv(raw), from_gymnasium(raw.observation_space), from_gymnasium(raw.action_space))
    act = memoryview(np.ascontiguousarray(action).tobytes())
    out = memoryview(bytearray(int(np.prod(raw.observation_space.shape)) * raw.observation_space.dtype.itemsize))

    # Both reset at each episode's end (a fallen Hopper steps at another cost) and start
    # from the same state.
    def bare() -> None:
        raw.reset(seed=0)
        for _ in range(args.steps):
            if any(raw.step(action)[2:4]):
                raw.reset()

    def worker() -> None:
        raw.reset(seed=0)
        for _ in range(args.steps):
            if any(hosted.step_into(act, out)[1:3]):
                raw.reset()

    # The client's infos: as the worker encodes them, parsed from JSON as the session does.
    info = raw.step(action)[4]
    got = hosted.step_into(act, out)[3]  # JSON text, or a dict that Rust writes as JSON
    text = got if isinstance(got, str) else json.dumps(got)
    infos = [json.loads(text) for _ in range(args.envs)]
    n = args.envs
    client = AsyncVectorEnv.__new__(AsyncVectorEnv)
    batches = max(1, args.steps // n)

    def client_infos() -> None:
        for _ in range(batches):
            client._info([dict(i) for i in infos], None, n)

    def gymnasium_infos() -> None:
        b = _Batch(n)
        for _ in range(batches):
            merged: dict = {}
            for k in range(n):
                merged = b._add_info(merged, info, k)

    t_bare = t_worker = float("inf")
    for _ in range(args.rounds):  # in alternation
        t_bare = min(t_bare, best_us(bare, args.steps, 1))
        t_worker = min(t_worker, best_us(worker, args.steps, 1))
    t_client = best_us(client_infos, batches * n, args.rounds)
    t_sync = best_us(gymnasium_infos, batches * n, args.rounds)
    assert decode_info(infos[0]).keys() == info.keys()
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
    raw.close()



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
