"""Reference frames of Gymnasium's MuJoCo v5 envs (`render_mode="rgb_array"`), for
envhub-mujoco's rendering parity test.

For each run (env id, constructor kwargs such as `width`, `camera_name` or
`default_camera_config`, seed) this makes the env with `gym.make`, resets it with the seed and
renders, then takes a few batches of random float32 actions and renders after each batch. It
records the actions and every frame (`height`, `width`, and the RGB bytes as hex), so the Rust
side can replay the same actions and compare its frames with these. Rendering uses EGL
(`MUJOCO_GL=egl`, set here), as the Rust renderer does; without a GPU both draw with Mesa's
software EGL.

Run by `adapters/mujoco/tests/render.rs`; by hand:
    python tests/python/support/mujoco_render_reference.py > frames.json
"""

from __future__ import annotations

import json
import os
import sys

os.environ["MUJOCO_GL"] = "egl"

import gymnasium as gym
import numpy as np

# (env id, kwargs, seed, steps before each later frame). Hopper's default camera is free (not
# tracking), so after 80 steps the hopper has moved in the frame; Ant's default camera looks at
# the median of its geoms at the first render; Reacher's is the plain free camera.
RUNS = [
    ("Hopper-v5", {}, 0, [40, 40]),
    (
        "Hopper-v5",
        {
            "width": 320,
            "height": 240,
            "default_camera_config": {"distance": 5.0, "azimuth": 120.0, "lookat": [0.5, 0.0, 0.8]},
        },
        1,
        [30],
    ),
    ("Ant-v5", {}, 0, [30]),
    ("Ant-v5", {"camera_name": "track", "width": 200, "height": 150}, 2, [30]),
    ("Reacher-v5", {}, 0, [20]),
    ("Reacher-v5", {"camera_id": -1, "width": 64, "height": 48}, 3, [10]),
    ("Humanoid-v5", {"width": 240, "height": 240}, 0, [10]),
]


def python_kwargs(kwargs: dict) -> dict:
    """JSON kwargs as a Gymnasium user passes them: `lookat` as a numpy array."""
    out = dict(kwargs)
    if "default_camera_config" in out:
        cam = dict(out["default_camera_config"])
        if "lookat" in cam:
            cam["lookat"] = np.array(cam["lookat"], dtype=np.float64)
        out["default_camera_config"] = cam
    return out


def frame_of(env: gym.Env) -> dict:
    rgb = np.ascontiguousarray(env.render(), dtype=np.uint8)
    return {"height": int(rgb.shape[0]), "width": int(rgb.shape[1]), "rgb": rgb.tobytes().hex()}


def record(env_id: str, kwargs: dict, seed: int, batches: list[int]) -> dict:
    env = gym.make(env_id, render_mode="rgb_array", **python_kwargs(kwargs))
    rng = np.random.default_rng(seed + 1000)
    env.reset(seed=seed)
    frames = [{"actions": [], **frame_of(env)}]
    low, high = env.action_space.low, env.action_space.high
    for n in batches:
        actions = []
        for _ in range(n):
            action = rng.uniform(low, high).astype(np.float32)
            env.step(action)
            actions.append([float(a) for a in action])
        frames.append({"actions": actions, **frame_of(env)})
    env.close()
    return {"env_id": env_id, "kwargs": kwargs, "seed": seed, "frames": frames}


def main() -> None:
    runs = [record(*run) for run in RUNS]
    json.dump({"gymnasium": gym.__version__, "runs": runs}, sys.stdout)


if __name__ == "__main__":
    main()
