"""Steps/s of a Python-hosted Gymnasium env through envhub against gymnasium's
`AsyncVectorEnv` with the same envs, in one run.

    .venv/bin/python python/bench/bench_hosted.py [--env CartPole-v1] [--envs 8] [--workers 2] [--seconds 3]

envhub: `make_vec` over a registry entry pinned to the `gymnasium` adapter (so the env runs
in Python inside `python -m envhub.worker` processes, not natively), `num_workers` workers.
Gymnasium: `AsyncVectorEnv(shared_memory=True)` with `num_envs` processes. Random actions
from a pre-drawn pool; autoreset on in both.

With `--vector-entry-point` the env is Gymnasium's own vectorised implementation
(`vectorization_mode: vector_entry_point`, e.g. `CartPoleVectorEnv`), served whole by each
worker (`EnvAdapter.make_vec`); the peer is then that vector env stepped in this process
(the ceiling: no IPC at all), so the ratio is what serving it out of process costs.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import textwrap
import time

import envhub
import gymnasium
import numpy as np


def rate(step, actions, seconds: float, num_envs: int) -> float:
    for a in actions[:20]:
        step(a)
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step(actions[n % len(actions)])
        n += 1
    return n * num_envs / (time.perf_counter() - start)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--env", default="CartPole-v1")
    p.add_argument("--envs", type=int, default=8)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--vector-entry-point", action="store_true")
    args = p.parse_args()
    kwargs = ", kwargs: {vectorization_mode: vector_entry_point}" if args.vector_entry_point else ""
    reg = os.path.join(tempfile.mkdtemp(), "bench.yaml")
    with open(reg, "w") as f:
        f.write(
            textwrap.dedent(
                f"""\
                environments:
                  - {{id: hosted, name: hosted, framework: gymnasium, env_id: {args.env}, adapter: gymnasium, robot_type: custom, env_type: floor{kwargs}}}
                """
            )
        )
    probe = gymnasium.make(args.env)
    probe.action_space.seed(0)
    actions = [np.stack([probe.action_space.sample() for _ in range(args.envs)]) for _ in range(256)]
    probe.close()

    envs = envhub.make_vec("hosted", args.envs, registry=reg, num_workers=args.workers)
    envs.reset(seed=0)
    hub = rate(envs.step, actions, args.seconds, args.envs)
    envs.close()

    if args.vector_entry_point:
        peer, gym_envs = "gymnasium_vector_entry_point_in_process", gymnasium.make_vec(args.env, args.envs, "vector_entry_point")
    else:
        peer = "gymnasium_async"
        gym_envs = gymnasium.vector.AsyncVectorEnv([lambda: gymnasium.make(args.env)] * args.envs, shared_memory=True)
    gym_envs.reset(seed=0)
    asy = rate(gym_envs.step, actions, args.seconds, args.envs)
    gym_envs.close()

    print(
        json.dumps(
            {
                "env": args.env,
                "num_envs": args.envs,
                "envhub_python_hosted_workers": args.workers,
                "envhub_steps_per_s": round(hub),
                f"{peer}_steps_per_s": round(asy),
                "ratio": round(hub / asy, 2),
                "cpus": os.cpu_count(),
            }
        )
    )


if __name__ == "__main__":
    main()
