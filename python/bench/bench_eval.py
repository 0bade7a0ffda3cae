"""Evaluation speed: `envhub eval` against the peers, in one run, as episodes per minute.

    python python/bench/bench_eval.py metaworld [--episodes 10] [--num-envs 10]
    python python/bench/bench_eval.py overhead [--steps 20000]

`metaworld`: Meta-World MT10 with Meta-World's scripted policies, `--episodes` per task,
through envhub's evaluation (`envhub.evaluation.experts:metaworld` in the catalog's
`metaworld` environment, `--num-envs` envs) against `metaworld.evaluation.evaluation` over
Gymnasium's `AsyncVectorEnv` (`gym.make_vec("Meta-World/MT10", vector_strategy="async")`,
one subprocess per task, as Meta-World's own evaluation runs it), in that environment.
Both step the same simulator with the same policies; the ratio is what each harness adds.

`overhead`: the harness's own cost per env step beyond the session's step: a constant
policy on `gym-pendulum` (a native env that never terminates, whose step costs about a microsecond), one long
episode per env, through `evaluate` against `make_vec` stepped by hand with the same
actions; fixed costs (imports, session start, results files) cancel out in the difference
of a long and a short run. Reported per env step, in microseconds.

Prints one JSON line per comparison; the figures in docs/guide/eval.md come from here. On a shared
machine the wall-clock ratio moves with the other jobs' load, so `metaworld` also gives each
side's CPU seconds (its processes' user + system time, children included) and the load
average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

REFERENCE = """
import json, sys, time, warnings
import numpy as np
import gymnasium as gym
import metaworld
from metaworld.evaluation import evaluation, _get_task_names
from metaworld.policies import ENV_POLICY_MAP
warnings.simplefilter("ignore")
t0 = time.perf_counter()
envs = gym.make_vec("Meta-World/MT10", vector_strategy="async", seed=1)
names = _get_task_names(envs)
experts = [ENV_POLICY_MAP[n]() for n in names]

class Agent:
    def eval_action(self, obs):
        return np.stack([np.asarray(p.get_action(o), dtype=np.float32) for p, o in zip(experts, obs)])
    def reset(self, mask):
        pass

mean, _, rates, returns = evaluation(Agent(), envs, num_episodes=EPISODES)
envs.close()
print(json.dumps({"seconds": time.perf_counter() - t0, "mean": mean}))
"""


def metaworld_python() -> str:
    from envhub._cli import BINARY

    done = subprocess.run([str(BINARY), "env", "sync", "metaworld"], capture_output=True, text=True, check=True)
    found = re.search(r"^metaworld: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
    if not found:
        raise SystemExit(f"cannot find the metaworld environment: {done.stdout}{done.stderr}")
    return f"{found.group(1)}/bin/python"


def cpu_seconds() -> float:
    """User + system seconds of this process and its children that have been waited for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def metaworld(episodes: int, num_envs: int) -> dict:
    from envhub.evaluation import evaluate

    python = metaworld_python()
    load = os.getloadavg()[0]
    code = REFERENCE.replace("EPISODES", str(episodes))
    c0 = cpu_seconds()
    ref = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True)
    reference_cpu = cpu_seconds() - c0
    reference = json.loads(ref.stdout.strip().splitlines()[-1])
    c0 = cpu_seconds()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        results = evaluate(
            "metaworld-mt10",
            "envhub.evaluation.experts:metaworld",
            policy_env="metaworld",
            episodes=episodes,
            num_envs=num_envs,
            out=out,
            progress=False,
        )
    ours = time.perf_counter() - t0
    ours_cpu = cpu_seconds() - c0
    total = 10 * episodes
    return {
        "bench": "metaworld-mt10-scripted",
        "episodes": total,
        "envhub_episodes_per_min": round(total / ours * 60, 1),
        "metaworld_async_episodes_per_min": round(total / reference["seconds"] * 60, 1),
        "ratio": round(reference["seconds"] / ours, 2),
        "envhub_cpu_s": round(ours_cpu, 1),
        "metaworld_cpu_s": round(reference_cpu, 1),
        "load_average": [round(load, 2), round(os.getloadavg()[0], 2)],
        "envhub_success": results["summary"]["success_rate"],
        "metaworld_success": reference["mean"],
        "num_envs": num_envs,
    }


def overhead(steps: int, num_envs: int) -> dict:
    import envhub
    from envhub.evaluation import evaluate

    def constant(observations, tasks):
        return np.zeros((len(observations), 1), dtype=np.float32)

    def harness(horizon: int) -> float:
        bench = {
            "description": "Pendulum (never terminates), one long episode per env: the harness's own cost per step",
            "entries": ["gym-pendulum"],
            "episodes_per_task": num_envs,
            "init": {"seed_start": 0},
            "horizon": horizon,
            "success": {"rule": "none"},
        }
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as out:
            evaluate(bench, constant, num_envs=num_envs, out=out, progress=False)
        return time.perf_counter() - t0

    def by_hand(horizon: int) -> float:
        t0 = time.perf_counter()
        envs = envhub.make_vec("gym-pendulum", num_envs, max_episode_steps=horizon + 1)
        envs.reset(seed=0)
        actions = np.zeros((num_envs, 1), dtype=np.float32)
        for _ in range(horizon):
            envs.step(actions)
        envs.close()
        return time.perf_counter() - t0

    # Fixed costs (imports, session start, results files) cancel in the difference of a run
    # of `long` steps and one of `short`; a first run of each warms imports up.
    long, short = steps // num_envs, steps // num_envs // 5
    harness(short), by_hand(short)
    ours = harness(long) - harness(short)
    raw = by_hand(long) - by_hand(short)
    env_steps = (long - short) * num_envs
    return {
        "bench": "harness-overhead",
        "env_steps": env_steps,
        "evaluate_us_per_env_step": round(ours / env_steps * 1e6, 2),
        "make_vec_us_per_env_step": round(raw / env_steps * 1e6, 2),
        "harness_us_per_env_step": round((ours - raw) / env_steps * 1e6, 2),
        "num_envs": num_envs,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["metaworld", "overhead"])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--num-envs", type=int, default=10)
    parser.add_argument("--steps", type=int, default=20000)
    args = parser.parse_args()
    if args.what == "metaworld":
        print(json.dumps(metaworld(args.episodes, args.num_envs)))
    else:
        print(json.dumps(overhead(args.steps, args.num_envs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
