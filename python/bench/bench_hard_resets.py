"""Hard resets of robosuite and LIBERO with and without the worker's caches
(`envhub.worker.hosted.compiled_models`, `render_contexts`, `sensor_checks`, as each suite's adapter
installs them): CPU seconds per reset, each mode in a fresh interpreter of the suite's own
environment, alternated `--rounds` times, best of each.

    envhub env run robosuite -- python/bench/bench_hard_resets.py robosuite Stack
    envhub env run libero -- python/bench/bench_hard_resets.py libero libero_spatial

The env has the catalog's cameras (two, 128x128 for LIBERO's, 84x84 for robosuite's) and
is reset `--resets` times after it is made; the observations of both modes are compared too.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def make(suite: str, task: str, cached: bool):
    if suite == "robosuite":
        import robosuite

        freeze_imports(cached)
        env = robosuite.make(
            task,
            robots="Panda",
            has_renderer=False,
            has_offscreen_renderer=True,
            use_camera_obs=True,
            camera_names=["agentview", "robot0_eye_in_hand"],
            camera_heights=84,
            camera_widths=84,
            ignore_done=True,
        )
        return env, env.reset
    from envhub.worker.hosted import libero

    libero.ensure_config()
    libero.use_assets()
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    freeze_imports(cached)
    tasks = benchmark.get_benchmark(task)()
    env = OffScreenRenderEnv(bddl_file_name=tasks.get_task_bddl_file_path(0), camera_heights=128, camera_widths=128)
    return env, env.reset


def freeze_imports(cached: bool) -> None:
    """What the adapters do once the suite is imported, before the first env."""
    if cached:
        from envhub.worker.hosted import sensor_checks

        sensor_checks.freeze_imports()


def one_run(suite: str, task: str, cached: bool, resets: int) -> dict:
    import numpy as np

    if cached:  # as each suite's adapter installs them
        from envhub.worker.hosted import compiled_models, render_contexts, sensor_checks

        if suite == "robosuite":
            compiled_models.install()
        else:
            render_contexts.install(scenes_repeat=True)
        sensor_checks.install()
    env, reset = make(suite, task, cached)
    reset()
    digest = hashlib.sha256()
    cpu, wall = time.process_time(), time.perf_counter()
    for i in range(resets):
        np.random.seed(i)
        if hasattr(env, "rng"):
            env.rng.bit_generator.state = np.random.default_rng(i).bit_generator.state
        obs = reset()
        for key in sorted(obs):
            digest.update(np.ascontiguousarray(obs[key]).tobytes())
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    return {"cpu": cpu / resets, "wall": wall / resets, "digest": digest.hexdigest()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("suite", choices=["robosuite", "libero"])
    parser.add_argument("task", help="robosuite's env name, or LIBERO's suite (task 0 of it)")
    parser.add_argument("--resets", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--mode", choices=["plain", "cached"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.mode:
        print(json.dumps(one_run(args.suite, args.task, args.mode == "cached", args.resets)))
        return 0
    best: dict[str, dict] = {}
    for _ in range(args.rounds):
        for mode in ("plain", "cached"):
            cmd = [sys.executable, __file__, args.suite, args.task, "--resets", str(args.resets), "--mode", mode]
            done = subprocess.run(cmd, capture_output=True, text=True, check=True)
            got = json.loads(done.stdout.strip().splitlines()[-1])
            if mode not in best or got["cpu"] < best[mode]["cpu"]:
                best[mode] = got
    plain, cached = best["plain"], best["cached"]
    print(
        f"{args.suite} {args.task}: {args.resets} resets, best of {args.rounds}: CPU per reset "
        f"{plain['cpu']:.3f} s plain, {cached['cpu']:.3f} s cached ({cached['cpu'] / plain['cpu']:.2f}x); "
        f"wall {plain['wall']:.3f} s, {cached['wall']:.3f} s; observations "
        f"{'bit for bit equal' if plain['digest'] == cached['digest'] else 'DIFFER'}"
    )
    return 0 if plain["digest"] == cached["digest"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
