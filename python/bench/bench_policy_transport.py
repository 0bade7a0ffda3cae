"""How a `--policy-env` policy gets its observations: shared memory (the arena) against the
pickled pipe it replaced, in one run, on a LIBERO-sized batch.

    python python/bench/bench_policy_transport.py [--envs 16] [--side 256] [--rounds 50]

The policy (zeros) runs in another interpreter, as `--policy-env` runs it; each batch is
`--envs` observations of two `side`x`side`x3 uint8 cameras and an 8-float state. Both ways go
through the same `EnvPolicy` and child; the pipe way sends the arrays inside the pickled
request (what the child still accepts without an arena). Prints one JSON line: milliseconds
per batch for each, and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

POLICY = "import numpy as np\ndef act(obs, tasks):\n    return [np.zeros(7, np.float32) for _ in obs]\n"


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--side", type=int, default=256)
    p.add_argument("--rounds", type=int, default=50)
    args = p.parse_args()
    from envhub.evaluation.policy import Episode, Request, Task
    from envhub.evaluation.policy_env import EnvPolicy

    folder = tempfile.mkdtemp(prefix="envhub-bench-")
    with open(os.path.join(folder, "zeros.py"), "w") as f:
        f.write(POLICY)
    policy = EnvPolicy(f"{folder}/zeros.py:act", [sys.executable], env_name="(this interpreter)")
    episode = Episode(Task("bench", "t", "e", "", 0), 0)
    rng = np.random.default_rng(0)
    shape = (args.side, args.side, 3)
    requests = [
        Request(i, episode, 0, {"agentview": rng.integers(0, 256, shape, dtype=np.uint8),
                                "wrist": rng.integers(0, 256, shape, dtype=np.uint8), "state": rng.normal(size=8)})
        for i in range(args.envs)
    ]

    def shared() -> None:
        policy.act(requests)

    def pipe() -> None:
        policy._call("act", list(requests))

    best: dict[str, float] = {}
    try:
        for way in (shared, pipe, shared, pipe):  # interleaved; the best of two per way
            way()
            t0 = time.perf_counter()
            for _ in range(args.rounds):
                way()
            ms = (time.perf_counter() - t0) / args.rounds * 1e3
            best[way.__name__] = min(best.get(way.__name__, ms), ms)
    finally:
        policy.close()
    print(json.dumps({
        "batch": f"{args.envs} x (2 x {args.side}x{args.side}x3 uint8 + 8 float64)",
        "shared_memory_ms": round(best["shared"], 3),
        "pickled_pipe_ms": round(best["pipe"], 3),
        "ratio": round(best["pipe"] / best["shared"], 2),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
