"""What `envhub eval`'s runner costs per env step beyond the session's own calls (issue 27).

    .venv/bin/python py-client/bench/bench_eval_overhead.py

gym-pendulum (native), 1 env, a constant-action callable, 20 episodes x 200 steps, 3 runs.
The session's make_vec, reset, send, recv and close are timed where the runner calls them;
the rest of the run (the policy call, requests, action checks, bookkeeping, the durable
episode log) is the harness's, divided by the env steps.
"""

from __future__ import annotations

import tempfile
import time

import envhub
import envhub.evaluation.runner as runner
import envhub.vector as vector
import numpy as np
from envhub.evaluation import evaluate

spent = [0.0]
run_time = [0.0]


def timed(f):
    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return f(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t

    return wrapper


for name in ("reset", "send", "recv", "close"):
    setattr(vector.VectorEnv, name, timed(getattr(vector.VectorEnv, name)))
envhub.make_vec = timed(envhub.make_vec)
original_run = runner.Runner.run


def run(self, skip):
    t = time.perf_counter()
    original_run(self, skip)
    run_time[0] = time.perf_counter() - t


runner.Runner.run = run
BENCH = {
    "name": "pendulum",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 20,
    "init": {"seed_start": 0},
    "horizon": 200,
    "success": "none",
}
CONST = np.zeros((1, 1), np.float32)


def main() -> None:
    best = None
    for _ in range(3):
        spent[0] = 0.0
        r = evaluate(BENCH, lambda o, t: CONST[: len(o)], out=tempfile.mkdtemp(), progress=False)
        steps = r["run"]["env_steps"]
        over = (run_time[0] - spent[0]) / steps
        best = over if best is None else min(best, over)
        print(f"run {run_time[0]:.3f} s, session calls {spent[0]:.3f} s, {steps} steps: {over * 1e6:.1f} us/step")
    print(f"harness beyond the session: best {best * 1e6:.1f} us per env step")


if __name__ == "__main__":
    main()
