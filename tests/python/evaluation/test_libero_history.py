"""LIBERO episodes do not depend on the episodes run before them on the same env.

For task 0 of each LIBERO suite, one session of two envs (one worker), every reset seeded 7
as the protocol seeds it: both new envs start episode 1 (init state 1); then env 0 runs
episode 0 (init state 0, a few steps that move the arm) and episode 1 again. Its
observation at the start of that episode equals env 1's, a new env's, bit for bit (both
cameras and every state). (LIBERO-90's kitchens failed this
before `hosted/libero.py`'s `FreshScenes`: 10 % of the pixels differed, the states did not.)
For LIBERO-90 it is also vla-eval's first episode of a new env, LIBERO in-process: made,
`seed(7)`, `reset()`, `set_init_state(init_states[1])`.

Skipped with the reason where LIBERO's environment cannot be built, failed instead under
ENVHUB_LIBERO_REQUIRED=1 or ENVHUB_SUITES_REQUIRED=1 (`libero_python` of support/libero_env.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from harness import import_envhub
from libero_env import WITH_ENVHUB, libero_python

envhub = import_envhub()

from envhub.client.factory import make_vec  # noqa: E402

SUITES = ["libero-spatial", "libero-object", "libero-goal", "libero-10", "libero-90"]
CAMERA = 128
SETTLE = np.array([0, 0, 0, 0, 0, 0, -1], np.float32)
MOVE = np.array([0.5, 0.3, -0.4, 0.1, 0, 0, 1], np.float32)

REFERENCE = """
import sys
import numpy as np
from envhub.worker.hosted.libero import ensure_config, use_assets
ensure_config(); use_assets()
from libero.libero import benchmark
from libero.libero.envs import OffScreenRenderEnv

tasks = benchmark.get_benchmark("libero_90")()
env = OffScreenRenderEnv(bddl_file_name=tasks.get_task_bddl_file_path(0), camera_heights=CAMERA, camera_widths=CAMERA)
env.seed(7)
env.reset()
obs = env.set_init_state(tasks.get_task_init_states(0)[1])
np.savez(sys.argv[1], **{k: np.asarray(v) for k, v in obs.items()})
"""


def _row(obs, i):
    return {k: np.array(v[i]) for k, v in obs.items()}


# slow: two LIBERO envs per suite, each episode's env built anew (~1 min a suite on two cores)
@pytest.mark.slow
@pytest.mark.parametrize("suite", SUITES)
def test_an_episode_equals_itself_on_a_fresh_env(tmp_path, suite):
    python = libero_python()
    envs = make_vec(suite, 2, 1, "disabled", max_episode_steps=100, task=0,
                    camera_heights=CAMERA, camera_widths=CAMERA)
    try:
        # Episode 1 on both new envs (a reset's options go to every env it resets).
        obs, _ = envs.reset(seed=[7, 7], options={"init_state": 1})
        fresh = _row(obs, 1)
        only_0 = np.array([True, False])
        envs.reset(seed=[7, None], options={"init_state": 0, "reset_mask": only_0})
        for t in range(12):  # env 0: episode 0, the arm moved
            envs.send(np.stack([SETTLE if t < 4 else MOVE]), [0])
            envs.recv()
        obs, _ = envs.reset(seed=[7, None], options={"init_state": 1, "reset_mask": only_0})
        after = _row(obs, 0)
    finally:
        envs.close()
    assert set(after) == set(fresh)
    for key in after:
        np.testing.assert_array_equal(after[key], fresh[key], err_msg=f"{suite}: {key}")
    if suite != "libero-90":
        return
    import subprocess

    ref_file = tmp_path / "ref.npz"
    env = {**WITH_ENVHUB, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    code = REFERENCE.replace("CAMERA", str(CAMERA))
    done = subprocess.run([python, "-c", code, str(ref_file)], capture_output=True, text=True, timeout=900, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    ref = np.load(ref_file)
    for key in after:
        np.testing.assert_array_equal(after[key], ref[key], err_msg=f"vla-eval's first episode: {key}")
