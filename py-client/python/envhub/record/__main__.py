"""`python -m envhub.record ID --episodes N --out DIR [--num-envs K] [--policy module:function]
[--success-only] [--no-video] [--repo-id R] [--max-episode-steps S] [--seed S]`, or
`python -m envhub.record ID --video out.mp4 [--steps N] [--policy module:function]`."""

from __future__ import annotations

import argparse
import sys


class _Line:
    """A progress line when tqdm is not installed."""

    def __init__(self, total: int) -> None:
        self.total, self.n = total, 0

    def update(self, k: int) -> None:
        self.n += k
        print(f"\r{min(self.n, self.total)}/{self.total} episodes", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        print(file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="envhub record", description=__doc__.split("\n")[0])
    p.add_argument("id", help="catalog entry id, e.g. mujoco-ant")
    p.add_argument("--episodes", type=int, help="episodes to write")
    p.add_argument("--out", help="dataset directory (LeRobot v3; appended to when it exists)")
    p.add_argument("--num-envs", type=int, default=1)
    p.add_argument("--policy", help="module:function taking the batched observation")
    p.add_argument("--success-only", action="store_true", help="keep successful episodes only")
    p.add_argument("--no-video", action="store_true", help="no render() video")
    p.add_argument("--repo-id", help="the dataset's repo id (default envhub/ID)")
    p.add_argument("--max-episode-steps", type=int)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--video", help="write the first env's render() frames to this MP4 instead")
    p.add_argument("--steps", type=int, default=300, help="steps for --video")
    a = p.parse_args(argv)

    from . import record, record_video
    from ._run import load_policy

    try:
        policy = load_policy(a.policy) if a.policy else None
        extra = {"max_episode_steps": a.max_episode_steps} if a.max_episode_steps else {}
        if a.video:
            n = record_video(a.id, a.video, steps=a.steps, policy=policy, seed=a.seed, **extra)
            print(f"wrote {n} frames to {a.video}")
            return 0
        if a.episodes is None or a.out is None:
            p.error("`--episodes` and `--out` are needed (or `--video FILE`)")
        try:
            from tqdm import tqdm

            bar = tqdm(total=a.episodes, unit="ep")
        except ImportError:
            bar = _Line(a.episodes)
        try:
            stats = record(
                a.id,
                a.episodes,
                a.out,
                policy=policy,
                num_envs=a.num_envs,
                repo_id=a.repo_id,
                filter="success" if a.success_only else "all",
                video=not a.no_video,
                seed=a.seed,
                progress=bar.update,
                **extra,
            )
        finally:
            bar.close()
    except (ValueError, TypeError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(
        f"wrote {stats['episodes_written']} episodes to {a.out}"
        f" ({stats['episodes_filtered']} filtered out, {stats['episodes_dropped']} dropped)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
