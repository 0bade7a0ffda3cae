"""`envhub.sb3`: Stable-Baselines3's `VecEnv` contract, checked against what SB3's own
`DummyVecEnv` does with the same Gymnasium envs (a reference loop written out here, so the
check runs without SB3 and torch), plus SB3's PPO on it when SB3 is installed."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip

envhub = import_envhub()
import envhub.sb3  # noqa: E402 - after the skip check

N, LIMIT, STEPS, SEED = 4, 20, 300, 5


class DummyVecEnvReference:
    """What SB3's `DummyVecEnv.step_wait`/`reset` do, over Gymnasium's CartPole."""

    def __init__(self) -> None:
        self.envs = [gym.make("CartPole-v1", max_episode_steps=LIMIT) for _ in range(N)]

    def reset(self, seed: int) -> np.ndarray:
        return np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(self.envs)])

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        obs, rews, dones, infos = [], [], [], []
        for env, a in zip(self.envs, actions, strict=True):
            o, r, term, trunc, info = env.step(int(a))
            info = dict(info)
            info["TimeLimit.truncated"] = trunc and not term
            if term or trunc:
                info["terminal_observation"] = o
                o, _ = env.reset()
            obs.append(o), rews.append(r), dones.append(term or trunc), infos.append(info)
        return np.stack(obs), np.array(rews, np.float32), np.array(dones), infos


def _registry_envs():
    return envhub.sb3.make_vec("gym-cartpole", N, 2, max_episode_steps=LIMIT, step_timeout=60)


def _factory_envs():
    fns = [lambda: gym.make("CartPole-v1", max_episode_steps=LIMIT) for _ in range(N)]
    return envhub.sb3.wrap(envhub.AsyncVectorEnv(fns, autoreset_mode="SameStep", num_workers=2, step_timeout=60))


@pytest.mark.parametrize("make", [_registry_envs, _factory_envs], ids=["make_vec", "AsyncVectorEnv"])
def test_step_reset_and_infos_match_sb3s_dummy_vec_env(make):
    venv = make()
    ref = DummyVecEnvReference()
    try:
        assert venv.num_envs == N and venv.observation_space == ref.envs[0].observation_space
        assert venv.action_space == ref.envs[0].action_space
        assert venv.seed(SEED) == [SEED + i for i in range(N)]
        np.testing.assert_array_equal(venv.reset(), ref.reset(SEED))
        assert venv.reset_infos == [{} for _ in range(N)]
        rng = np.random.default_rng(0)
        finished = truncated = 0
        for t in range(STEPS):
            actions = rng.integers(0, 2, N)
            venv.step_async(actions)
            obs, rews, dones, infos = venv.step_wait()
            r_obs, r_rews, r_dones, r_infos = ref.step(actions)
            np.testing.assert_array_equal(obs, r_obs, err_msg=f"step {t}")
            assert rews.dtype == np.float32 and np.array_equal(rews, r_rews)
            assert dones.dtype == np.bool_ and np.array_equal(dones, r_dones), t
            assert [sorted(i) for i in infos] == [sorted(i) for i in r_infos], (t, infos, r_infos)
            for got, want in zip(infos, r_infos, strict=True):
                assert got["TimeLimit.truncated"] == want["TimeLimit.truncated"]
                if "terminal_observation" in want:
                    np.testing.assert_array_equal(got["terminal_observation"], want["terminal_observation"])
            finished += int(dones.sum())
            truncated += sum(i["TimeLimit.truncated"] for i in infos)
        assert finished > 20 and truncated > 0  # both kinds of episode end were checked
    finally:
        venv.close()


def test_seed_is_used_once_and_attributes_known_here():
    venv = envhub.sb3.make_vec("gym-cartpole", 2, 1, step_timeout=60)
    try:
        venv.seed(3)
        first = venv.reset().copy()
        venv.seed(3)
        np.testing.assert_array_equal(venv.reset(), first)
        assert not np.array_equal(venv.reset(), first)  # the seed applied once only
        assert venv.get_attr("render_mode") == [None, None]
        assert venv.get_attr("action_space", indices=[1]) == [venv.action_space]
        assert venv.env_is_wrapped(gym.Wrapper) == [False, False]
        with pytest.raises(AttributeError, match="known here"):
            venv.get_attr("gravity")
        with pytest.raises(envhub.InvalidStateError, match="cannot reach"):
            venv.env_method("close_door")
        with pytest.raises(envhub.InvalidStateError, match="cannot reach"):
            venv.set_attr("gravity", 1.0)
        with pytest.raises(envhub.InvalidStateError, match="without a prior"):
            venv.step_wait()
    finally:
        venv.close()


def test_a_vector_env_of_another_autoreset_mode_is_refused():
    venv = envhub.make_vec("gym-cartpole", 2, 1)
    try:
        with pytest.raises(envhub.InvalidConfigError, match="same_step"):
            envhub.sb3.wrap(venv)
    finally:
        venv.close()


def test_importing_envhub_does_not_import_sb3():
    code = "import sys, envhub, envhub.sb3; assert 'stable_baselines3' not in sys.modules; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr


SB3_MISSING = importlib.util.find_spec("stable_baselines3") is None


@pytest.mark.skipif(
    SB3_MISSING,
    reason="stable-baselines3 is not installed (it needs torch; see README: "
    "pip install torch --index-url https://download.pytorch.org/whl/cpu stable-baselines3)",
)
def test_sb3_ppo_learns_on_mujoco_ant():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor

    mujoco_or_skip(envhub)
    venv = envhub.sb3.make_vec("mujoco-ant", 8, step_timeout=120)
    try:
        assert isinstance(venv, VecEnv)
        model = PPO("MlpPolicy", VecMonitor(venv), n_steps=32, batch_size=64, n_epochs=1, seed=0)
        model.learn(total_timesteps=512)
        assert model.num_timesteps >= 512
    finally:
        venv.close()


def test_attributes_and_methods_reach_the_envs_of_an_async_vector_env():
    fns = [lambda: gym.make("CartPole-v1") for _ in range(3)]
    venv = envhub.sb3.wrap(envhub.AsyncVectorEnv(fns, autoreset_mode="SameStep", step_timeout=60))
    try:
        venv.reset()
        assert venv.get_attr("gravity") == [9.8, 9.8, 9.8]
        venv.set_attr("gravity", 1.5, indices=[1])
        assert venv.get_attr("gravity") == [9.8, 1.5, 9.8]
        assert venv.env_method("get_wrapper_attr", "gravity", indices=[1, 2]) == [1.5, 9.8]
    finally:
        venv.close()
