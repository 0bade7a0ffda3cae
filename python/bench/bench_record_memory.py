"""The recorder's peak memory: many envs with large camera frames, a writer that falls behind.

    ENVHUB_TEST_ADAPTERS=1 .venv/bin/python python/bench/bench_record_memory.py \\
        [--envs 64] [--size 480] [--steps 200] [--queue-mib 512] [--encode-threads 2] [--json]

The envs are envhub's `null` test env with a `(size, size, 3)` uint8 image observation (no
simulation: each env fills its frame with its step count), so the envs step far faster than
x264 encodes `envs` videos and the writer's queue fills: the recorder's memory is what its
bounds allow. Episodes last `--episode-steps` steps, so episodes end and are committed during
the run. Reported, for this process (the recorder; the envs run in worker processes): the
resident set before recording (envs made and reset), its peak while recording and closing
(`VmHWM`, reset at the start), the queue's peak bytes, and the most threads seen.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import textwrap
import threading
import time
import warnings
from pathlib import Path

import numpy as np

os.environ.setdefault("ENVHUB_TEST_ADAPTERS", "1")

import envhub

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: null-env
        name: Null
        framework: envhub
        env_id: Null-v0
        robot_type: custom
        env_type: floor
        task_tags: [nothing]
        description: Does no work.
    """
)


def _status(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])  # kB, or a count
    raise KeyError(field)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--size", type=int, default=480)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--episode-steps", type=int, default=50)
    p.add_argument("--queue-mib", type=float, default=512)
    p.add_argument("--encode-threads", type=int, default=None)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--json", action="store_true")
    args = p.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="envhub-bench-mem-"))
    (tmp / "registry.yaml").write_text(REGISTRY)
    env = envhub.make_vec("null-env", args.envs, num_workers=args.workers, registry=str(tmp / "registry.yaml"),
                          frame=[args.size, args.size, 3], max_episode_steps=args.episode_steps)
    env.reset(seed=0)
    rec = envhub.RecordEpisodes(env, str(tmp / "ds"), fps=30, task="nothing",
                                queue_bytes=int(args.queue_mib * 2**20), encode_threads=args.encode_threads)
    actions = np.zeros(args.envs, np.int64)
    before = _status("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
    threads = [threading.active_count(), _status("Threads")]
    stop = threading.Event()

    def watch() -> None:
        while not stop.wait(0.05):
            threads[1] = max(threads[1], _status("Threads"))

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    start = time.monotonic()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec.reset(seed=0)
        for _ in range(args.steps):
            rec.step(actions)
        stepped = time.monotonic() - start
        rec.close()
    elapsed = time.monotonic() - start
    stop.set()
    watcher.join()
    peak = _status("VmHWM")
    frame = args.size * args.size * 3
    result = {
        "envs": args.envs,
        "size": args.size,
        "steps": args.steps,
        "step_mib": args.envs * frame / 2**20,
        "queue_budget_mib": args.queue_mib,
        "queue_peak_mib": rec._writer.queue.peak / 2**20 if rec._writer else 0.0,
        "rss_before_mib": before / 1024,
        "rss_peak_mib": peak / 1024,
        "rss_peak_over_before_mib": (peak - before) / 1024,
        "threads_max": threads[1],
        "episodes_written": rec.stats["episodes_written"],
        "steps_waited": rec.stats["steps_waited"],
        "seconds_stepping": round(stepped, 2),
        "seconds_with_close": round(elapsed, 2),
    }
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in result.items():
            print(f"{k:>26}: {v:.1f}" if isinstance(v, float) else f"{k:>26}: {v}")


if __name__ == "__main__":
    main()
