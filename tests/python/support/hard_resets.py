"""Run in robosuite's interpreter by pyenv/test_suites.py, plainly or with the worker's caches of
hard resets installed (`envhub.worker.hosted.compiled_models`, `render_contexts`, `sensor_checks`),
with two cameras:
- `stack`: robosuite's `Stack`, whose scene is the same at every reset, reset four times;
- `lift`: robosuite's `Lift`, whose XML is drawn from the reset seed (the cube's size), reset
  with seeds 1 to 3, again, and 3 to 1, the pool cut to two contexts: more scenes that repeat
  than contexts the pool keeps, so a context is dropped and freed between the renders of
  others, which are handed on after.
Modes: `plain`, `cached`, and `repeat` (cached, every scene taken to be built again, as LIBERO's
adapter installs the pool: a context waits from its scene's first build on).
A step after each reset. Prints JSON: a digest of every observation, and how many models were
compiled, render contexts built and camera frames rendered."""

from __future__ import annotations

import hashlib
import json
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import mujoco
import numpy as np


def main(task: str, mode: str) -> None:
    cached = mode in ("cached", "repeat")
    compile_xml = mujoco.MjModel.from_xml_string
    if cached:
        from envhub.worker.hosted import compiled_models, render_contexts, sensor_checks

        compiled_models.install()
        render_contexts.install(scenes_repeat=mode == "repeat")
        sensor_checks.install()
        render_contexts.MAX_KEPT = 2
    import robosuite
    from robosuite.utils import binding_utils

    counts = {"compiles": 0, "contexts": 0, "renders": 0}

    def counted_compile(xml, assets=None):
        counts["compiles"] += 1
        return compile_xml(xml) if assets is None else compile_xml(xml, assets)

    # Counted below the cache: the compiles that really happen.
    if cached:
        from envhub.worker.hosted import compiled_models

        compiled_models._installed._compile = counted_compile
    else:
        mujoco.MjModel.from_xml_string = staticmethod(counted_compile)
    new_context = binding_utils.MjRenderContextOffscreen.__init__

    def counted_context(self, *args, **kwargs):
        counts["contexts"] += 1
        new_context(self, *args, **kwargs)

    binding_utils.MjRenderContextOffscreen.__init__ = counted_context
    render = binding_utils.MjSim.render

    def counted_render(self, *args, **kwargs):
        counts["renders"] += 1
        return render(self, *args, **kwargs)

    binding_utils.MjSim.render = counted_render
    env = robosuite.make(
        task.capitalize(),
        robots="Panda",
        has_renderer=False,
        has_offscreen_renderer=True,
        use_camera_obs=True,
        camera_names=["agentview", "robot0_eye_in_hand"],
        camera_heights=48,
        camera_widths=64,
        ignore_done=True,
    )
    digest = hashlib.sha256()
    low, high = env.action_spec
    for episode in range(4) if task == "stack" else [1, 2, 3] * 2 + [3, 2, 1]:
        np.random.seed(episode)  # robosuite 1.4 draws from numpy's global generator
        if hasattr(env, "rng"):  # 1.5 from its own
            env.rng.bit_generator.state = np.random.default_rng(episode).bit_generator.state
        for obs in (env.reset(), env.step((low + high) / 2 + episode * 0.1)[0]):
            for key in sorted(obs):
                digest.update(key.encode())
                digest.update(np.ascontiguousarray(obs[key]).tobytes())
    env.close()
    print(json.dumps({"digest": digest.hexdigest(), **counts}))


if __name__ == "__main__":
    if sys.argv[2] not in ("plain", "cached", "repeat"):
        sys.exit(f"unknown mode {sys.argv[2]!r}: plain, cached or repeat")
    main(sys.argv[1], sys.argv[2])
