"""Runs several of the LeRobot plugin tests' steps in one LeRobot interpreter, for
test_lerobot_plugin.py: LeRobot's import (torch, its policies, its envs) costs each
interpreter about 9 s of CPU, half a minute of wall time on a busy two-core machine, and the
tests took one interpreter per step.

    python lerobot_steps.py STEPS.json

STEPS is a list, done in order:
- `["policy", SPEC.json, DIR]`: a random-init ACT saved as LeRobot saves one (`lerobot_policy.py`);
- `["rollout", SPEC.json, OUT.npz]`: fixed actions through an env config (`lerobot_rollout.py`);
- `["dataset", DIR]`: a tiny local LeRobot dataset (two episodes of 480x480 frames);
- `["eval", ARG...]`, `["train", ARG...]`: the real `lerobot-eval` / `lerobot-train`, as their
  console scripts run them (their `main()` reading `sys.argv`).
"""

from __future__ import annotations

import json
import sys


def tiny_dataset(root: str) -> None:
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {
        "observation.image": {"dtype": "image", "shape": (480, 480, 3), "names": ["height", "width", "channels"]},
        "observation.state": {"dtype": "float32", "shape": (4,), "names": None},
        "action": {"dtype": "float32", "shape": (4,), "names": None},
    }
    ds = LeRobotDataset.create("envhub/tiny", fps=80, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(2):
        for _ in range(8):
            ds.add_frame(
                {
                    "observation.image": rng.integers(0, 256, (480, 480, 3), dtype=np.uint8),
                    "observation.state": rng.standard_normal(4).astype(np.float32),
                    "action": rng.uniform(-1, 1, 4).astype(np.float32),
                    "task": "Push the puck to a goal",
                }
            )
        ds.save_episode()
    ds.finalize()


def console_script(name: str, args: list[str]) -> None:
    """`lerobot-eval ARGS` or `lerobot-train ARGS`: the console script's entry point."""
    if name == "eval":
        from lerobot.scripts.lerobot_eval import main
    else:
        from lerobot.scripts.lerobot_train import main
    saved = sys.argv
    sys.argv = [f"lerobot-{name}", *args]
    try:
        main()
    finally:
        sys.argv = saved


def main(steps_path: str) -> None:
    import lerobot_policy
    import lerobot_rollout

    with open(steps_path) as f:
        steps = json.load(f)
    for kind, *args in steps:
        print(f"lerobot_steps: {kind}", flush=True)
        if kind == "policy":
            lerobot_policy.main(*args)
        elif kind == "rollout":
            lerobot_rollout.main(*args)
        elif kind == "dataset":
            tiny_dataset(*args)
        elif kind in ("eval", "train"):
            console_script(kind, args)
        else:
            raise SystemExit(f"unknown step `{kind}`: policy, rollout, dataset, eval or train")


if __name__ == "__main__":
    main(sys.argv[1])
