"""Session start of a suite's Python environment with warm workers (forked from the
environment's fork server) against cold ones (`ENVHUB_WARM_WORKERS=0`: a fresh interpreter
per worker that imports the suite), in one run.

    .venv/bin/python python/bench/bench_warm_workers.py [--rounds 3] [--suite metaworld]

Each round runs a fresh client process per mode; in it, session start is `make_vec` + the
first `reset` + `close`, timed for the process's first session and its second:

- `metaworld`: Meta-World MT10 as `envhub eval` starts it (`metaworld-reach`, 10 envs, one per
  task through the `env_name` list, 2 workers), in the `metaworld` environment;
- `gymnasium`: CartPole in a small provisioned environment (Gymnasium only, another CPython),
  where the interpreter's own start is most of a worker's.

Warm: the first session starts the fork server (imports the suite once) and forks its workers;
the second forks from the running server. Cold: every session starts its workers from scratch.
The environment is built first if it is missing (`envhub env sync`, uv from PyPI).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
ENVHUB_BIN = REPO / "target" / "release" / "envhub"
MT10 = [
    "reach-v3",
    "push-v3",
    "pick-place-v3",
    "door-open-v3",
    "drawer-open-v3",
    "drawer-close-v3",
    "button-press-topdown-v3",
    "peg-insert-side-v3",
    "window-open-v3",
    "window-close-v3",
]

GYM_REGISTRY = textwrap.dedent(
    """\
    python_envs:
      py312:
        python: "3.12"
        requirements: ["gymnasium==1.2.0"]
        env: {ENVHUB_TEST_MARK: "py312"}
    environments:
      - id: cartpole-py312
        name: CartPole on Python 3.12
        framework: gymnasium
        env_id: CartPole-v1
        adapter: gymnasium
        robot_type: custom
        env_type: floor
        python_env: py312
    """
)

CLIENT = textwrap.dedent(
    """\
    import json, sys, time
    import envhub

    id, n, workers, registry, kwargs = json.loads(sys.argv[1])
    out = []
    for _ in range(2):
        start = time.perf_counter()
        envs = envhub.make_vec(id, n, num_workers=workers, registry=registry, **kwargs)
        envs.reset(seed=0)
        envs.close()
        out.append(time.perf_counter() - start)
    print(json.dumps(out))
    """
)


def sessions(spec: list, warm: bool) -> list[float]:
    env = {**os.environ, "ENVHUB_WARM_WORKERS": "1" if warm else "0"}
    done = subprocess.run(
        [sys.executable, "-c", CLIENT, json.dumps(spec)], capture_output=True, text=True, env=env, timeout=900
    )
    if done.returncode != 0:
        raise SystemExit(f"the client failed: {done.stderr.strip()[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def sync(registry: str | None, name: str) -> None:
    args = [str(ENVHUB_BIN), *(["--registry", registry] if registry else []), "env", "sync", name]
    done = subprocess.run(args, capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        raise SystemExit(f"`envhub env sync {name}` failed: {done.stderr.strip()[-2000:]}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--suite", choices=["metaworld", "gymnasium"], action="append")
    args = parser.parse_args()
    suites = args.suite or ["gymnasium", "metaworld"]
    specs = {}
    if "gymnasium" in suites:
        registry = os.path.join(tempfile.mkdtemp(prefix="envhub-bench-warm-"), "registry.yaml")
        Path(registry).write_text(GYM_REGISTRY)
        sync(registry, "py312")
        specs["gymnasium: CartPole x4, 2 workers"] = ["cartpole-py312", 4, 2, registry, {}]
    if "metaworld" in suites:
        sync(None, "metaworld")
        specs["metaworld: MT10 x10, 2 workers"] = ["metaworld-reach", 10, 2, None, {"env_name": MT10}]
    print(f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, {args.rounds} rounds (median)")
    for label, spec in specs.items():
        runs: dict[str, list[list[float]]] = {"cold": [], "warm": []}
        for _ in range(args.rounds):
            for mode in ("cold", "warm"):
                runs[mode].append(sessions(spec, mode == "warm"))
        med = {m: [statistics.median(r[i] for r in runs[m]) for i in range(2)] for m in runs}
        print(f"{label}")
        print(f"  cold: first session {med['cold'][0]:.2f} s, second {med['cold'][1]:.2f} s")
        print(f"  warm: first session {med['warm'][0]:.2f} s (starts the fork server), second {med['warm'][1]:.2f} s")
        print(f"  second session, cold / warm: {med['cold'][1] / med['warm'][1]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
