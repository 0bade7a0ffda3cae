"""The `maniskill` adapter against ManiSkill3 itself: `maniskill-pick-cube` (PickCube-v1, CPU
simulator, state observations) through envhub equals the same env stepped in this process
with the same seeds and actions, and a vector session over 2 Python workers runs.

Skipped unless ManiSkill is importable here and the worker's interpreter (ENVHUB_PYTHON,
else this one) reports the adapter available: ManiSkill is not in requirements-dev.txt,
and SAPIEN needs a Vulkan device even for state observations (a GPU driver, or Mesa's
lavapipe; see `envhub/worker/hosted/maniskill.py`). To run it:
`ENVHUB_PYTHON=<python with mani-skill> <that python> -m pytest tests/python/worker/hosted/test_maniskill.py`.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()

if importlib.util.find_spec("mani_skill") is None:
    pytest.skip(
        "ManiSkill3 is not installed for this interpreter (`pip install mani-skill`); "
        "the reference run needs it in-process",
        allow_module_level=True,
    )

ENTRY = "maniskill-pick-cube"
ENV_ID = "PickCube-v1"
LIMIT = 50  # PickCube-v1's registered max_episode_steps


@pytest.fixture(scope="module", autouse=True)
def adapter_available() -> None:
    info = envhub.AdapterRegistry().get("maniskill")
    if not info["available"]:
        pytest.skip(f"the maniskill adapter is unavailable: {info['reason']} (hint: {info['hint']})")


def reference(seed: int):
    """PickCube-v1 in this process, through ManiSkill's own numpy wrapper for CPU envs."""
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401 - registers the ids
    from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper

    env = CPUGymWrapper(gym.make(ENV_ID, obs_mode="state", sim_backend="cpu", num_envs=1))
    obs, info = env.reset(seed=seed)
    return env, obs, info


def actions(n: int, shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, (n, *shape)).astype(np.float32)


@pytest.fixture(scope="module")
def single():
    env = envhub.make(ENTRY)
    yield env
    env.close()


def test_spaces_and_limit(single):
    import gymnasium as gym

    assert single.observation_space == gym.spaces.Box(-np.inf, np.inf, (42,), np.float32)
    assert single.action_space == gym.spaces.Box(-1.0, 1.0, (8,), np.float32)
    assert single.max_episode_steps == LIMIT


def test_matches_maniskill_in_process(single):
    ref, ref_obs, ref_info = reference(seed=3)
    try:
        obs, info = single.reset(seed=3)
        assert obs.dtype == np.float32 and obs.shape == (42,)
        np.testing.assert_array_equal(obs, ref_obs)
        assert info["success"] is False and info["elapsed_steps"] == 0
        for t, a in enumerate(actions(LIMIT, (8,))):
            got = single.step(a)
            want = ref.step(a)
            np.testing.assert_array_equal(got[0], want[0], err_msg=f"obs at step {t + 1}")
            assert got[1] == pytest.approx(float(want[1]), abs=0), f"reward at step {t + 1}"
            assert (got[2], got[3]) == (bool(want[2]), bool(want[3])), f"done flags at step {t + 1}"
            assert got[4]["success"] == bool(want[4]["success"])
            assert got[4]["elapsed_steps"] == t + 1
        assert got[3] is True, "PickCube-v1 truncates at its 50th step"
    finally:
        ref.close()


def test_max_episode_steps_override():
    env = envhub.make(ENTRY, max_episode_steps=7)
    try:
        assert env.max_episode_steps == 7
        env.reset(seed=0)
        truncated = [env.step(a)[3] for a in actions(7, (8,))]
        assert truncated == [False] * 6 + [True]
    finally:
        env.close()


def test_make_vec_two_workers_matches_in_process():
    n, seed, steps = 4, 10, 20
    vec = envhub.make_vec(ENTRY, n, num_workers=2)
    refs = [reference(seed + i) for i in range(n)]
    try:
        assert vec.single_observation_space.shape == (42,)
        assert vec.num_workers == 2 and len(set(vec.worker_pids)) == 2
        obs, _ = vec.reset(seed=seed)  # env i is seeded with seed + i
        assert obs.shape == (n, 42) and obs.dtype == np.float32
        np.testing.assert_array_equal(obs, np.stack([r[1] for r in refs]))
        acts = actions(steps, (n, 8), seed=1)
        for t in range(steps):
            obs, reward, terminated, truncated, _ = vec.step(acts[t])
            want = [r[0].step(acts[t, i]) for i, r in enumerate(refs)]
            np.testing.assert_array_equal(obs, np.stack([w[0] for w in want]), err_msg=f"obs at step {t + 1}")
            np.testing.assert_array_equal(reward, np.array([float(w[1]) for w in want]))
            assert terminated.tolist() == [bool(w[2]) for w in want]
            assert truncated.tolist() == [bool(w[3]) for w in want] == [False] * n
    finally:
        vec.close()
        for r in refs:
            r[0].close()
