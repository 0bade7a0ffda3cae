"""The recorder's command line, which `envhub record` and `envhub run --video` run with the
hub's interpreter:

    python -m envhub.recording ID --episodes N --out DIR [--num-envs K] [--policy MODULE:FUNCTION]
        [--success-only] [--no-video] [--seed S] [--max-steps S] [--fps F] [--codec C] [--when-full wait|drop]
    python -m envhub.recording ID --video FILE.mp4 [--steps N] [--policy MODULE:FUNCTION] [--seed S]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from ..wire.errors import EnvHubError

#: The exit status when fewer episodes than asked were kept (`--max-steps`); `envhub record`
#: reads it.
FEWER_EPISODES = 3


class _Progress:
    """`[#####     ]  12/100 episodes  3.1/s` on stderr, redrawn in place on a terminal and
    every tenth of the way otherwise."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.start = time.monotonic()
        self.shown = -1
        self.last = -1

    def __call__(self, kept: int, total: int) -> None:
        tenth = kept * 10 // total
        if kept == self.last or (not self.tty and tenth == self.shown and kept != total):
            return
        self.shown, self.last = tenth, kept
        rate = kept / max(time.monotonic() - self.start, 1e-9)
        bar = "#" * (kept * 30 // total)
        line = f"[{bar:<30}] {kept:>{len(str(total))}}/{total} episodes  {rate:.1f}/s"
        print(f"\r{line}" if self.tty else line, end="" if self.tty else "\n", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.tty and self.shown >= 0:
            print(file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="envhub record", description="Record episodes into a LeRobot dataset.")
    p.add_argument("id", help="catalog entry id, e.g. mujoco-ant")
    p.add_argument("--episodes", type=int, help="episodes to keep")
    p.add_argument("--out", help="the dataset's folder (LeRobot v3.0; appended to when it holds one)")
    p.add_argument("--num-envs", type=int, default=1, help="envs stepped at once (default 1)")
    p.add_argument("--policy", metavar="MODULE:FUNCTION", help="policy(obs) -> actions; default: random")
    p.add_argument("--success-only", action="store_true", help="keep only episodes whose info says success")
    p.add_argument("--no-video", action="store_true", help="no video of render() frames")
    p.add_argument("--seed", type=int, default=0, help="seed of the first reset and of random actions")
    p.add_argument("--max-steps", type=int, help="stop after this many batched steps")
    p.add_argument("--fps", type=int, help="frames per second (default: the env's render_fps)")
    p.add_argument("--codec", help="video encoder (libx264, libsvtav1, libaom-av1, libopenh264)")
    p.add_argument("--when-full", choices=["wait", "drop"], default="wait",
                   help="when the writer falls behind: steps wait (default) or drop episodes")
    p.add_argument("--video", metavar="FILE", help="instead: write one env's render() frames to this MP4")
    p.add_argument("--steps", type=int, default=300, help="steps of the --video rollout (default 300)")
    a = p.parse_args(argv)

    from . import record, record_video
    from ._run import load_policy

    try:
        policy = load_policy(a.policy) if a.policy else None
        if a.video:
            n = record_video(a.id, a.video, steps=a.steps, policy=policy, seed=a.seed, fps=a.fps,
                             **({"codec": a.codec} if a.codec else {}))
            print(f"wrote {n} frames to {a.video}")
            return 0
        if a.episodes is None or a.out is None:
            p.error("`--episodes N` and `--out DIR` are required (or `--video FILE`)")
        progress = _Progress()
        try:
            options: dict = {"when_full": a.when_full, "fps": a.fps}
            if a.codec:
                options["codec"] = a.codec
            stats = record(
                a.id, a.episodes, a.out, num_envs=a.num_envs, policy=policy,
                keep="success" if a.success_only else "all", video=not a.no_video, seed=a.seed,
                max_steps=a.max_steps, progress=progress, recorder=options,
            )
        finally:
            progress.close()
    except (EnvHubError, ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted: the episodes that ended were written", file=sys.stderr)
        return 130
    notes = [f"{stats[k]} {k.split('_', 1)[1]}" for k in ("episodes_filtered", "episodes_dropped") if stats[k]]
    print(
        f"wrote {stats['episodes_written']} episodes ({stats['frames_kept']} frames, {stats['steps']} steps) "
        f"to {os.path.abspath(a.out)}" + (f"; {', '.join(notes)}" if notes else "")
    )
    return 0 if stats["episodes_written"] >= a.episodes else FEWER_EPISODES


if __name__ == "__main__":
    sys.exit(main())
