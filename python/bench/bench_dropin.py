"""Steps/s of `envhub.AsyncVectorEnv` against `gymnasium.vector.AsyncVectorEnv` on the same
env factories, in one run (ratios are what to read; absolute rates depend on the machine).

    .venv/bin/python python/bench/bench_dropin.py [--env CartPole-v1 Hopper-v5] [--envs 8] [--workers 2] [--seconds 3]

Both get `[lambda: gymnasium.make(env)] * envs` and the same pre-drawn random actions, with
Gymnasium's default next_step autoreset. Gymnasium runs one process per env; envhub runs
`--workers` worker processes (default: its own default, one per core). The two are measured
in alternation, `--rounds` times each, and the best round of each is kept (the machine may be
shared). PufferLib is not a peer here: see README.md ("PufferLib as a peer") for why it
cannot be installed next to the project's pins.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import envhub
import gymnasium
import numpy as np


def rate(envs, actions: list[np.ndarray], seconds: float) -> float:
    envs.reset(seed=0)
    for a in actions[:20]:
        envs.step(a)
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        envs.step(actions[n % len(actions)])
        n += 1
    return n * envs.num_envs / (time.perf_counter() - start)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--env", nargs="+", default=["CartPole-v1", "Hopper-v5"])
    p.add_argument("--envs", type=int, default=8)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args()
    for env_id in args.env:
        fns = [lambda env_id=env_id: gymnasium.make(env_id)] * args.envs
        probe = gymnasium.make(env_id)
        probe.action_space.seed(0)
        actions = [np.stack([probe.action_space.sample() for _ in range(args.envs)]) for _ in range(256)]
        probe.close()
        best = {"envhub": 0.0, "gymnasium": 0.0}
        workers = None
        for _ in range(args.rounds):
            ours = envhub.AsyncVectorEnv(fns, num_workers=args.workers)
            workers = ours.num_workers
            best["envhub"] = max(best["envhub"], rate(ours, actions, args.seconds))
            ours.close()
            ref = gymnasium.vector.AsyncVectorEnv(fns)
            best["gymnasium"] = max(best["gymnasium"], rate(ref, actions, args.seconds))
            ref.close()
        print(
            json.dumps(
                {
                    "env": env_id,
                    "num_envs": args.envs,
                    "envhub_workers": workers,
                    "gymnasium_processes": args.envs,
                    "envhub_steps_per_s": round(best["envhub"]),
                    "gymnasium_async_steps_per_s": round(best["gymnasium"]),
                    "envhub_over_gymnasium": round(best["envhub"] / best["gymnasium"], 2),
                    "cores": os.cpu_count(),
                    "load_avg_1m": round(os.getloadavg()[0], 2),
                }
            )
        )


if __name__ == "__main__":
    main()
