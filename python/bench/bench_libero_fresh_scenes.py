"""What building LIBERO's env anew for every episode costs (`hosted/libero.py`'s `FreshScenes`).

Runs in LIBERO's Python environment (it re-executes itself there through `envhub env run
libero`), in-process, the protocol's way to start an episode: `seed(7)`, `reset()`,
`set_init_state(k)`, with 256x256 cameras; once on LIBERO's env as it is (`plain`: a hard
reset, the scene rebuilt in the same env) and once through `FreshScenes` (the env built
anew first). One JSON line per suite: seconds of CPU (this process) and of wall clock per
episode start, and the ratio.

    .venv/bin/python python/bench/bench_libero_fresh_scenes.py [--episodes 4]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time


def measure(suite: str, episodes: int) -> dict:
    from envhub.worker.hosted import render_contexts, sensor_checks
    from envhub.worker.hosted.libero import FreshScenes, ensure_config, use_assets

    ensure_config()
    use_assets()
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    # As the adapter sets the process up.
    render_contexts.install(scenes_repeat=True)
    sensor_checks.install()
    tasks = benchmark.get_benchmark(suite)()
    bddl = tasks.get_task_bddl_file_path(0)
    init = tasks.get_task_init_states(0)

    def make():
        return OffScreenRenderEnv(bddl_file_name=bddl, ignore_done=True, camera_heights=256, camera_widths=256)

    out = {"suite": suite, "episodes": episodes}
    for mode in ("plain", "fresh"):
        env = FreshScenes(make) if mode == "fresh" else make()
        env.reset()  # as the adapter's env is reset once when made
        cpu, wall = time.process_time(), time.perf_counter()
        for k in range(episodes):
            env.seed(7)
            env.reset()
            env.set_init_state(init[k % len(init)])
        out[f"{mode}_cpu_s"] = round((time.process_time() - cpu) / episodes, 3)
        out[f"{mode}_wall_s"] = round((time.perf_counter() - wall) / episodes, 3)
        env.close()
    out["cpu_ratio"] = round(out["fresh_cpu_s"] / out["plain_cpu_s"], 2)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--suites", nargs="+", default=["libero_spatial", "libero_90"])
    p.add_argument("--inside", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if not args.inside:
        from envhub._cli import BINARY

        here = os.path.dirname(os.path.abspath(__file__))
        package = os.path.join(here, os.pardir, "python")
        env = {**os.environ, "PYTHONPATH": os.path.abspath(package), "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
        command = [str(BINARY), "env", "run", "libero", "--", os.path.abspath(__file__), "--inside",
                   "--episodes", str(args.episodes), "--suites", *args.suites]
        return subprocess.run(command, env=env).returncode
    for suite in args.suites:
        print(json.dumps(measure(suite, args.episodes)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
