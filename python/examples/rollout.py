"""A random-policy rollout through the Python package: `make demo` runs it.

    python python/examples/rollout.py [env-id] [num-envs] [steps]
"""

from __future__ import annotations

import sys
import time

import envhub
import gymnasium


def main() -> None:
    env_id = sys.argv[1] if len(sys.argv) > 1 else "gym-cartpole"
    num_envs = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    steps = int(sys.argv[3]) if len(sys.argv) > 3 else 5000
    match = envhub.match_task_to_env(envhub.TaskSpec("balance a pole on a cart"))
    print(f"task 'balance a pole on a cart' -> {match.entry.id} ({match.match_reason})")
    envs = gymnasium.wrappers.vector.RecordEpisodeStatistics(envhub.make_vec(env_id, num_envs, num_workers=1))
    envs.reset(seed=0)
    returns = []
    start = time.perf_counter()
    for _ in range(steps):
        _, _, _, _, info = envs.step(envs.action_space.sample())
        if "episode" in info:
            returns.extend(info["episode"]["r"][info["_episode"]].tolist())
    seconds = time.perf_counter() - start
    envs.close()
    mean = sum(returns) / len(returns) if returns else float("nan")
    print(
        f"{env_id}: {steps * num_envs} steps in {seconds:.2f} s ({steps * num_envs / seconds:,.0f} steps/s) "
        f"over {num_envs} envs in Python; {len(returns)} episodes, mean return {mean:.1f}"
    )


if __name__ == "__main__":
    main()
