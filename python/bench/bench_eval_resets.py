"""The evaluation runner on episodes that end at different times with slow resets: the
ready-env runner (an ended env resets alone while the other workers step) against the
synchronous one (`ENVHUB_EVAL_READY_ENVS=0`: every round waits for every env, ended envs
reset together), as episodes per minute, in alternation, in one run.

    python python/bench/bench_eval_resets.py [--envs 4] [--episodes 24] [--reset-ms 300]
           [--step-ms 5] [--rounds 2]

The env is a Python-hosted Gymnasium env (a user adapter registered by the script) whose
reset waits `--reset-ms` and whose step waits `--step-ms`, and whose episode lasts 10 to 60
steps, drawn from its reset seed (the benchmark seeds every episode): a suite's costly reset
(LIBERO's takes 0.5-0.9 s) among short episodes that end at different times, as a policy
that succeeds early makes them. The waits are sleeps, standing for a simulator that runs on
a core of its own: on a machine with fewer cores than workers the figure would be the CPU's,
not the runner's. One worker per env. Both runners give the same results table (checked).
Prints one JSON line per run and a comparison line.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import textwrap
import time

ENV_MODULE = textwrap.dedent(
    """\
    import os
    import time

    import envhub
    import gymnasium
    import numpy as np

    RESET_S = float(os.environ["BENCH_RESET_MS"]) / 1000
    STEP_S = float(os.environ["BENCH_STEP_MS"]) / 1000


    class SlowResets(gymnasium.Env):
        observation_space = gymnasium.spaces.Box(-1e9, 1e9, (4,), np.float32)
        action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            time.sleep(RESET_S)
            self.length = int(self.np_random.integers(10, 61))
            self.t = 0
            return np.zeros(4, np.float32), {}

        def step(self, action):
            time.sleep(STEP_S)
            self.t += 1
            obs = np.full(4, self.t, np.float32)
            return obs, float(action[0]), self.t >= self.length, False, {}


    class SlowResetsAdapter(envhub.EnvAdapter):
        name = "bench_slow_resets"
        frameworks = ["bench_slow_resets"]
        requires = ["gymnasium"]
        description = "slow resets, episodes of 10-60 steps"

        def make(self, env_id, config):
            return SlowResets()
    """
)

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: bench-slow-resets
        name: Slow resets, episodes of 10-60 steps
        framework: bench_slow_resets
        env_id: SlowResets-v0
        robot_type: custom
        env_type: floor
    """
)

POLICY = textwrap.dedent(
    """\
    import numpy as np

    def act(observations, tasks):
        return np.full((len(observations), 1), 0.5, np.float32)
    """
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--episodes", type=int, default=24)
    parser.add_argument("--reset-ms", type=float, default=300)
    parser.add_argument("--step-ms", type=float, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()

    folder = tempfile.mkdtemp(prefix="envhub-bench-resets-")
    with open(os.path.join(folder, "envhub_bench_slow_resets.py"), "w") as f:
        f.write(ENV_MODULE)
    with open(os.path.join(folder, "bench_policy.py"), "w") as f:
        f.write(POLICY)
    registry = os.path.join(folder, "registry.yaml")
    with open(registry, "w") as f:
        f.write(REGISTRY)
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [folder, os.environ.get("PYTHONPATH")]))
    os.environ["BENCH_RESET_MS"] = str(args.reset_ms)
    os.environ["BENCH_STEP_MS"] = str(args.step_ms)
    sys.path.insert(0, folder)
    import envhub
    import envhub_bench_slow_resets
    from envhub.evaluation import evaluate

    envhub.AdapterRegistry().register(envhub_bench_slow_resets.SlowResetsAdapter)
    bench = {
        "name": "slow-resets",
        "entries": ["bench-slow-resets"],
        "episodes_per_task": args.episodes,
        "init": {"seed_start": 0},
        "horizon": 100,
        "success": "none",
    }

    def run(ready: bool, k: int) -> tuple[float, list]:
        os.environ["ENVHUB_EVAL_READY_ENVS"] = "1" if ready else "0"
        start = time.perf_counter()
        results = evaluate(
            bench,
            f"{folder}/bench_policy.py:act",
            num_envs=args.envs,
            workers=args.envs,
            registry=registry,
            out=os.path.join(folder, f"{'ready' if ready else 'sync'}-{k}"),
            progress=False,
        )
        seconds = time.perf_counter() - start
        table = sorted((e["task"], e["index"], e["length"], e["return"], e["error"]) for e in results["episodes"])
        return seconds, table

    rates: dict[bool, list[float]] = {True: [], False: []}
    tables = {}
    for k in range(args.rounds):
        for ready in (True, False):
            seconds, tables[ready] = run(ready, k)
            rate = args.episodes / seconds * 60
            rates[ready].append(rate)
            name = "ready envs" if ready else "synchronous"
            print(json.dumps({"runner": name, "round": k, "seconds": round(seconds, 2), "episodes_per_min": round(rate, 1)}))
    assert tables[True] == tables[False], "the runners gave different results"
    assert all(e[4] is None for e in tables[True]), tables[True]
    best = {ready: max(r) for ready, r in rates.items()}
    print(
        json.dumps(
            {
                "comparison": "ready envs / synchronous runner, episodes per minute (best of rounds)",
                "envs": args.envs,
                "episodes": args.episodes,
                "reset_ms": args.reset_ms,
                "step_ms": args.step_ms,
                "ratio": round(best[True] / best[False], 2),
                "ratios_per_round": [round(a / b, 2) for a, b in zip(rates[True], rates[False], strict=True)],
            }
        )
    )


if __name__ == "__main__":
    main()
