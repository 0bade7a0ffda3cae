"""Meta-World MT10 with Meta-World's scripted policies, E episodes per task (issue 27):
`envhub eval metaworld-mt10` (the policy in the catalog's `metaworld` environment, N envs)
against `metaworld.evaluation.evaluation` over Gymnasium's `AsyncVectorEnv` (10 envs, one
per task) in that environment's interpreter. Wall clock of one run each, process start and
env making included on both sides (envhub caches Meta-World's goal sets after its first
run: run once before timing).

    .venv/bin/python py-client/bench/bench_eval_mt10.py E N
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time

from envhub.evaluation import evaluate
from envhub.evaluation.policy_env import env_python

REFERENCE = """
import time, warnings, numpy as np, gymnasium as gym, metaworld
from metaworld.evaluation import evaluation, _get_task_names
from metaworld.policies import ENV_POLICY_MAP
warnings.simplefilter("ignore")
envs = gym.make_vec("Meta-World/MT10", vector_strategy="async", seed=1)
experts = [ENV_POLICY_MAP[n]() for n in _get_task_names(envs)]
class Agent:
    def eval_action(self, obs):
        return np.stack([np.asarray(p.get_action(o), dtype=np.float32) for p, o in zip(experts, obs)])
    def reset(self, mask):
        pass
mean, _, _, _ = evaluation(Agent(), envs, num_episodes=EPISODES)
envs.close()
print(mean)
"""


def main() -> None:
    episodes, num_envs = int(sys.argv[1]), int(sys.argv[2])
    python = env_python("metaworld")
    t = time.perf_counter()
    done = subprocess.run([python, "-c", REFERENCE.replace("EPISODES", str(episodes))], capture_output=True, text=True)
    ref = time.perf_counter() - t
    t = time.perf_counter()
    r = evaluate(
        "metaworld-mt10",
        "envhub.evaluation.experts:metaworld",
        policy_env="metaworld",
        episodes=episodes,
        num_envs=num_envs,
        out=tempfile.mkdtemp(),
        progress=False,
    )
    ours = time.perf_counter() - t
    n = 10 * episodes
    print(f"reference evaluation(): {ref:.1f} s, {n / ref * 60:.1f} episodes/min, success {done.stdout.strip()}")
    print(
        f"envhub eval ({num_envs} envs): {ours:.1f} s, {n / ours * 60:.1f} episodes/min, "
        f"success {r['summary']['success_rate']}; ratio {ref / ours:.2f}x"
    )


if __name__ == "__main__":
    main()
