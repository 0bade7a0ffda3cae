"""Recording's cost on throughput: env steps per second of `N` envs stepped with random
actions, plain and under `RecordEpisodes` (without frames, and with `render()` frames encoded
to MP4), in one run, with the ratios and the datasets' sizes.

    python py-client/bench/bench_record.py [--id mujoco-ant] [--envs 64] [--steps 60]
        [--max-episode-steps 30]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import envhub
from envhub.record import RecordEpisodes


def _size(root: Path) -> int:
    return sum(f.stat().st_size for f in root.rglob("*") if f.is_file())


def run(id: str, envs: int, steps: int, mes: int, frames: bool, record: bool, root: Path | None):
    env = envhub.make_vec(id, envs, render_mode="rgb_array" if frames else None, max_episode_steps=mes)
    if record:
        env = RecordEpisodes(env, str(root), repo_id=f"bench/{id}", video=frames)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
        if frames and not record:
            env.render()  # the frames a recorder takes, without keeping them
    stepped = time.perf_counter() - t0
    env.close()  # the recorder drains its queue here
    total = time.perf_counter() - t0
    stats = getattr(env, "stats", None)
    return envs * steps / stepped, envs * steps / total, stats


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--id", default="mujoco-ant")
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--max-episode-steps", type=int, default=30)
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="envhub-bench-record-"))
    try:
        rows = []
        for frames in (False, True):
            base, _, _ = run(a.id, a.envs, a.steps, a.max_episode_steps, frames, False, None)
            root = tmp / f"frames{int(frames)}"
            rec, rec_total, stats = run(a.id, a.envs, a.steps, a.max_episode_steps, frames, True, root)
            rows.append((frames, base, rec, rec_total, stats, _size(root)))
            print(f"{a.id}, {a.envs} envs, {a.steps} steps, episodes of {a.max_episode_steps} steps")
            frames, base, rec, rec_total, stats, size = rows[-1]
            what = "with render() frames" if frames else "without frames"
            print(
                f"{what:22s} plain {base:9.0f} steps/s | recording {rec:9.0f} steps/s while stepping "
                f"({rec / base:.2f}x), {rec_total:9.0f} steps/s incl. draining the writer "
                f"({rec_total / base:.2f}x) | {stats['episodes_written']} episodes, "
                f"{size / 1e6:.2f} MB ({size / max(1, stats['episodes_written']) / 1e3:.0f} kB/episode)",
                flush=True,
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
