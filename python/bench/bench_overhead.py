"""What serving a Python env out of process costs (issue 20), in one run: steps/s of the same
Gymnasium envs stepped in-process (`SyncVectorEnv`, one core), through `envhub.AsyncVectorEnv`
with 1 and 2 workers, and through Gymnasium's `AsyncVectorEnv` (one process per env); the
ratios; and the per-env-step overhead of envhub with 1 worker over in-process stepping.

    .venv/bin/python python/bench/bench_overhead.py [--env CartPole-v1 Hopper-v5 HalfCheetah-v5]
        [--envs 8] [--seconds 2] [--rounds 2] [--policy] [--json]

Random actions from a pre-drawn pool; Gymnasium's default next_step autoreset everywhere;
each peer measured `--rounds` times in alternation, best round kept (the machine may be
shared). With `--policy`, a policy-in-the-loop figure as well (the first env whose actions
are a Box): a small numpy MLP (obs → 64 → 64 → action, tanh) evaluated on the batch's
observations between steps, as a PPO rollout does, in-process `SyncVectorEnv` against envhub
with 2 workers.

The per-env-step overhead is `(1 / envhub_1_worker - 1 / in_process)` in µs: what one env's
step costs more through one worker than in this interpreter (the worker and this process
run one after the other in lock-step, so the sum is what is compared).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable
from typing import Any

import envhub
import gymnasium
import numpy as np


def _rate(envs: Any, step: Callable[[int], Any], seconds: float, reset: Callable[[], Any] | None = None) -> float:
    """Env steps per second of `step` after a reset (`reset`, else `envs.reset(seed=0)`) and 20
    warm-up steps."""
    (reset or (lambda: envs.reset(seed=0)))()
    for i in range(20):
        step(i)
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step(n)
        n += 1
    return n * envs.num_envs / (time.perf_counter() - start)


def random_rate(envs: Any, actions: list[np.ndarray], seconds: float) -> float:
    pool = len(actions)
    return _rate(envs, lambda n: envs.step(actions[n % pool]), seconds)


class Mlp:
    """A small tanh MLP in numpy (float32), the shape of a PPO actor."""

    def __init__(self, obs_dim: int, act_dim: int, low: np.ndarray, high: np.ndarray) -> None:
        rng = np.random.default_rng(0)
        self.w = [
            rng.normal(0, 0.1, (obs_dim, 64)).astype(np.float32),
            rng.normal(0, 0.1, (64, 64)).astype(np.float32),
            rng.normal(0, 0.1, (64, act_dim)).astype(np.float32),
        ]
        self.low, self.high = low.astype(np.float32), high.astype(np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        h = np.tanh(obs.astype(np.float32) @ self.w[0])
        h = np.tanh(h @ self.w[1])
        return np.clip(np.tanh(h @ self.w[2]), self.low, self.high)


def policy_rate(envs: Any, policy: Mlp, seconds: float) -> float:
    state: dict[str, Any] = {}

    def reset() -> None:
        state["obs"] = envs.reset(seed=0)[0]

    def step(_: int) -> None:
        state["obs"] = envs.step(policy(state["obs"]))[0]

    return _rate(envs, step, seconds, reset)


def best(makers: dict[str, Callable[[], Any]], measure: Callable[[Any], float], rounds: int) -> dict[str, float]:
    out: dict[str, float] = {}
    for _ in range(rounds):
        for name, make in makers.items():
            envs = make()
            try:
                out[name] = max(out.get(name, 0.0), measure(envs))
            finally:
                envs.close()
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--env", nargs="+", default=["CartPole-v1", "Hopper-v5", "HalfCheetah-v5"])
    p.add_argument("--envs", type=int, default=8)
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument(
        "--policy", action="store_true", help="also the policy-in-the-loop figure (first env with a Box action space)"
    )
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    n = args.envs
    rows = []
    policy_measured = False
    for env_id in args.env:
        fns = [lambda env_id=env_id: gymnasium.make(env_id)] * n
        probe = gymnasium.make(env_id)
        probe.action_space.seed(0)
        actions = [np.stack([probe.action_space.sample() for _ in range(n)]) for _ in range(64)]
        makers = {
            "in_process": lambda fns=fns: gymnasium.vector.SyncVectorEnv(fns),
            "envhub_1": lambda fns=fns: envhub.AsyncVectorEnv(fns, num_workers=1),
            "envhub_2": lambda fns=fns: envhub.AsyncVectorEnv(fns, num_workers=2),
            "gymnasium_async": lambda fns=fns: gymnasium.vector.AsyncVectorEnv(fns, shared_memory=True),
        }
        r = best(makers, lambda e, actions=actions: random_rate(e, actions, args.seconds), args.rounds)
        row: dict[str, Any] = {"env": env_id, "num_envs": n, **{k: round(v) for k, v in r.items()}}
        row["overhead_us_per_env_step"] = round((1 / r["envhub_1"] - 1 / r["in_process"]) * 1e6, 1)
        row["envhub_1/in_process"] = round(r["envhub_1"] / r["in_process"], 2)
        row["envhub_2/in_process"] = round(r["envhub_2"] / r["in_process"], 2)
        row["envhub_2/gymnasium_async"] = round(r["envhub_2"] / r["gymnasium_async"], 2)
        if args.policy and not policy_measured and isinstance(probe.action_space, gymnasium.spaces.Box):
            policy_measured = True
            space = probe.action_space
            policy = Mlp(int(np.prod(probe.observation_space.shape)), int(np.prod(space.shape)), space.low, space.high)
            pr = best(
                {k: makers[k] for k in ("in_process", "envhub_2")},
                lambda e, policy=policy: policy_rate(e, policy, args.seconds),
                args.rounds,
            )
            row["policy_in_process"] = round(pr["in_process"])
            row["policy_envhub_2"] = round(pr["envhub_2"])
            row["policy_envhub_2/in_process"] = round(pr["envhub_2"] / pr["in_process"], 2)
        probe.close()
        rows.append(row)
        if args.json:
            print(json.dumps({**row, "cpus": os.cpu_count()}), flush=True)
    if not args.json:
        print(
            "| env | in-process Sync | envhub 1 worker | 2 workers | Gymnasium Async | overhead µs/env-step"
            " | 1w/in-proc | 2w/in-proc | 2w/Async |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(
                f"| {r['env']} | {r['in_process']:,} | {r['envhub_1']:,} | {r['envhub_2']:,} | {r['gymnasium_async']:,}"
                f" | {r['overhead_us_per_env_step']} | {r['envhub_1/in_process']} | {r['envhub_2/in_process']}"
                f" | {r['envhub_2/gymnasium_async']} |"
            )
        for r in rows:
            if "policy_in_process" in r:
                print(
                    f"policy in the loop ({r['env']} x {r['num_envs']}, numpy MLP): in-process {r['policy_in_process']:,},"
                    f" envhub 2 workers {r['policy_envhub_2']:,} steps/s, ratio {r['policy_envhub_2/in_process']}"
                )


if __name__ == "__main__":
    main()
