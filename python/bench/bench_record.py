"""What recording costs: env steps/s with and without `envhub.RecordEpisodes`, and file sizes.

    .venv/bin/python python/bench/bench_record.py [--id mujoco-half-cheetah] [--envs 64]
        [--steps 400] [--frame-steps 20] [--size 96] [--rounds 3] [--json]

Four runs of the same envs and pre-drawn random actions, alternated `--rounds` times so load
on the machine hits each alike; the median of each is reported:

- `plain`: `step()` only;
- `recorded`: `step()` through `RecordEpisodes(video=False)` (states, actions, rewards into a
  dataset; the writer thread keeps up or the step waits, so all of its cost is counted);
- `frames`: `step()` + `render()` every step (`render_mode="rgb_array"`, `--size` pixels a
  side): what drawing the frames costs without recording;
- `frames+video`: `step()` through `RecordEpisodes` with the `render()` video (x264).

Ratios `recorded / plain` and `frames+video / frames` are the recorder's overhead. Episodes are
cut at `--max-episode-steps` so episodes end and are written during the run; each run's
dataset is closed (every ended episode committed) before its clock stops. Sizes are the
datasets' bytes per frame: Parquet (data + episode metadata) and MP4.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import envhub
import numpy as np


def _bytes(root: Path, pattern: str) -> int:
    return sum(p.stat().st_size for p in root.glob(pattern))


def run(kind: str, a: argparse.Namespace, actions: np.ndarray, tmp: Path) -> dict:
    frames = kind in ("frames", "frames+video")
    steps = a.frame_steps if frames else a.steps
    env = envhub.make_vec(
        a.id, a.envs, render_mode="rgb_array" if frames else None, max_episode_steps=a.max_episode_steps,
        **({"width": a.size, "height": a.size} if frames and a.size else {}),
    )
    root = tmp / f"{kind}-{time.monotonic_ns()}"
    target = envhub.RecordEpisodes(env, str(root), video=frames) if kind in ("recorded", "frames+video") else env
    try:
        target.reset(seed=0)
        if frames and target is env:
            env.render()
        start = time.perf_counter()
        for t in range(steps):
            target.step(actions[t % len(actions)])
            if frames and target is env:
                env.render()
        if target is not env:
            target.close()  # commits what ended: part of the cost
        seconds = time.perf_counter() - start
    finally:
        if not env.closed:
            env.close()
    out = {"kind": kind, "env_steps_per_s": steps * a.envs / seconds}
    if root.exists():
        stats = target.stats
        frames_kept = max(stats["frames_kept"], 1)
        out |= {
            "episodes": stats["episodes_written"],
            "frames": stats["frames_kept"],
            "parquet_bytes_per_frame": (_bytes(root, "data/*/*.parquet") + _bytes(root, "meta/episodes/*/*.parquet"))
            / frames_kept,
            "mp4_bytes_per_frame": _bytes(root, "videos/*/*/*.mp4") / frames_kept,
            "waited_steps": stats["steps_waited"],
        }
        shutil.rmtree(root)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--id", default="mujoco-half-cheetah")
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=400, help="batched steps without frames")
    p.add_argument("--frame-steps", type=int, default=20, help="batched steps with frames")
    p.add_argument("--size", type=int, default=96, help="frame width and height (0: the env's own)")
    p.add_argument("--kinds", nargs="+", default=["plain", "recorded", "frames", "frames+video"])
    p.add_argument("--max-episode-steps", type=int, default=50)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--json", action="store_true")
    a = p.parse_args()
    warnings.simplefilter("ignore")
    probe = envhub.make_vec(a.id, 1)
    probe.action_space.seed(0)
    actions = np.stack([probe.action_space.sample() for _ in range(64)])  # batches of one env
    actions = np.repeat(actions, a.envs, axis=1) if actions.ndim > 1 else np.repeat(actions[:, None], a.envs, 1)
    probe.close()
    results: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(a.rounds):
            for kind in a.kinds:
                results.setdefault(kind, []).append(run(kind, a, actions, Path(tmp)))
    summary = {}
    for kind, rs in results.items():
        rate = statistics.median(r["env_steps_per_s"] for r in rs)
        summary[kind] = {**rs[-1], "env_steps_per_s": rate, "all_rates": [round(r["env_steps_per_s"]) for r in rs]}
    for name, (a_kind, b_kind) in {"recorded / plain": ("recorded", "plain"),
                                   "frames+video / frames": ("frames+video", "frames")}.items():
        if a_kind in summary and b_kind in summary:
            summary[name] = summary[a_kind]["env_steps_per_s"] / summary[b_kind]["env_steps_per_s"]
    if a.json:
        print(json.dumps({"id": a.id, "envs": a.envs, "size": a.size, **summary}, indent=2))
        return
    size = f"{a.size}x{a.size}" if a.size else "the env's size"
    print(f"{a.id}, {a.envs} envs, frames {size}, median of {a.rounds} rounds")
    for kind in a.kinds:
        r = summary[kind]
        line = f"  {kind:<13} {r['env_steps_per_s']:>10.0f} env steps/s  {r['all_rates']}"
        if "parquet_bytes_per_frame" in r:
            line += f"  parquet {r['parquet_bytes_per_frame']:.0f} B/frame, mp4 {r['mp4_bytes_per_frame']:.0f} B/frame"
        print(line)
    for name in ("recorded / plain", "frames+video / frames"):
        if name in summary:
            print(f"  {name:<22} {summary[name]:.3f}")


if __name__ == "__main__":
    main()
