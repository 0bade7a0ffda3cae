"""`envhub.make_vec` and `gymnasium.make_vec("envhub/<id>")`: Gymnasium's vector contract
(the three autoreset modes compared step by step with `SyncVectorEnv` over Gymnasium's own
envs), several workers, vector wrappers, and EnvPool-style `send`/`recv`."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from harness import import_envhub

envhub = import_envhub()

MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED]


def _reference(gym_id: str, n: int, mode: AutoresetMode):
    return gymnasium.make_vec(
        gym_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}
    )


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.value)
@pytest.mark.parametrize("workers", [1, 2])
def test_same_as_sync_vector_env(mode, workers):
    """Every autoreset mode gives what Gymnasium's `SyncVectorEnv` gives for the same seeds
    and actions, done flags, resets and final observations included."""
    n = 5
    ours = envhub.make_vec("gym-cartpole", n, num_workers=workers, autoreset_mode=mode)
    ref = _reference("CartPole-v1", n, mode)
    try:
        assert ours.metadata["autoreset_mode"] == mode
        assert ours.num_workers == workers
        o1, _ = ours.reset(seed=10)
        o2, _ = ref.reset(seed=10)
        np.testing.assert_allclose(o1, o2, atol=1e-6)
        rng = np.random.default_rng(0)
        dones = 0
        for _ in range(120):
            actions = rng.integers(0, 2, size=n)
            s1, s2 = ours.step(actions), ref.step(actions)
            np.testing.assert_allclose(s1[0], s2[0], atol=1e-5)
            np.testing.assert_allclose(s1[1], s2[1])
            np.testing.assert_array_equal(s1[2], s2[2])
            np.testing.assert_array_equal(s1[3], s2[3])
            if mode == AutoresetMode.SAME_STEP and "final_obs" in s2[4]:
                mask = s2[4]["_final_obs"]
                np.testing.assert_array_equal(s1[4]["_final_obs"], mask)
                for i in np.flatnonzero(mask):
                    np.testing.assert_allclose(s1[4]["final_obs"][i], s2[4]["final_obs"][i], atol=1e-5)
                assert "final_info" in s1[4] and s1[4]["_final_info"].tolist() == mask.tolist()
            done = s1[2] | s1[3]
            dones += int(done.sum())
            if mode == AutoresetMode.DISABLED and done.any():
                r1, _ = ours.reset(options={"reset_mask": done})
                r2, _ = ref.reset(options={"reset_mask": done})
                np.testing.assert_allclose(r1, r2, atol=1e-5)
        assert dones > 0
    finally:
        ours.close()
        ref.close()


def test_spaces_and_metadata():
    envs = envhub.make_vec("gym-pendulum", 4, num_workers=1)
    try:
        assert isinstance(envs, gymnasium.vector.VectorEnv)
        assert envs.single_observation_space.shape == (3,)
        assert envs.observation_space.shape == (4, 3)
        assert envs.action_space.shape == (4, 1)
        assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
        assert envs.metadata["render_fps"] == gymnasium.make("Pendulum-v1").metadata["render_fps"]
        obs, info = envs.reset(seed=0)
        assert obs in envs.observation_space and info == {}
        obs, rewards, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert rewards.dtype == np.float64 and terminated.dtype == np.bool_ and truncated.dtype == np.bool_
        assert rewards.flags.writeable  # small arrays are fresh copies
    finally:
        envs.close()


def test_seed_given_at_make_seeds_the_first_reset():
    envs = envhub.make_vec("gym-cartpole", 3, seed=7, num_workers=1)
    ref = _reference("CartPole-v1", 3, AutoresetMode.NEXT_STEP)
    try:
        np.testing.assert_allclose(envs.reset()[0], ref.reset(seed=7)[0], atol=1e-7)
    finally:
        envs.close()
        ref.close()


def test_seed_lists_and_autoreset_mode_names():
    envs = envhub.make_vec("gym-cartpole", 3, autoreset_mode="same_step", num_workers=1)
    try:
        assert envs.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
        a, _ = envs.reset(seed=[3, 4, 5])
        b, _ = envs.reset(seed=3)
        np.testing.assert_array_equal(a, b)
    finally:
        envs.close()
    with pytest.raises(envhub.InvalidConfigError, match="autoreset"):
        envhub.make_vec("gym-cartpole", 2, autoreset_mode="sometimes")


def test_vector_wrappers():
    envs = envhub.make_vec("gym-cartpole", 4, num_workers=1, max_episode_steps=30)
    envs = gymnasium.wrappers.vector.RecordEpisodeStatistics(envs)
    envs = gymnasium.wrappers.vector.NormalizeObservation(envs)
    envs = gymnasium.wrappers.vector.NormalizeReward(envs)
    try:
        envs.reset(seed=0)
        episodes = 0
        for _ in range(100):
            obs, _, _, _, info = envs.step(envs.action_space.sample())
            assert obs.shape == (4, 4)
            if "episode" in info:
                episodes += int(info["_episode"].sum())
                assert (info["episode"]["l"][info["_episode"]] <= 30).all()
        assert episodes > 0
    finally:
        envs.close()


def test_gymnasium_make_vec_passes_options():
    envs = gymnasium.make_vec("envhub/gym-pendulum", num_envs=2, g=9.81, max_episode_steps=7, num_workers=1)
    try:
        assert envs.max_episode_steps == 7 and envs.num_workers == 1
        envs.reset(seed=0)
        truncated = np.zeros(2, dtype=bool)
        for _ in range(7):
            _, _, _, truncated, _ = envs.step(envs.action_space.sample())
        assert truncated.all()
    finally:
        envs.close()


@pytest.mark.parametrize("workers", [1, 2])
def test_send_recv(workers):
    """EnvPool's async API: send to some envs, receive the first workers' results with their
    env ids; the others keep their state. Same trajectories as lock-step stepping."""
    n = 6
    async_envs = envhub.make_vec("gym-cartpole", n, num_workers=workers)
    sync_envs = envhub.make_vec("gym-cartpole", n, num_workers=1)
    try:
        async_envs.reset(seed=1)
        sync_envs.reset(seed=1)
        actions = np.array([0, 1, 0, 1, 1, 0])
        async_envs.send(actions)
        got: dict[int, np.ndarray] = {}
        while len(got) < n:
            obs, rewards, terminated, truncated, info = async_envs.recv()
            assert len(obs) == len(info["env_id"]) == len(rewards)
            for k, i in enumerate(info["env_id"]):
                got[int(i)] = np.array(obs[k])
        expected = sync_envs.step(actions)[0]
        for i in range(n):
            np.testing.assert_allclose(got[i], expected[i])
        # Only some envs: the results name exactly those.
        async_envs.send(np.array([1, 1]), env_ids=[0, 4])
        seen = []
        while len(seen) < 2:
            _, _, _, _, info = async_envs.recv()
            seen.extend(int(i) for i in info["env_id"])
        assert sorted(seen) == [0, 4]
        with pytest.raises(envhub.InvalidStateError, match="send"):
            async_envs.recv()
    finally:
        async_envs.close()
        sync_envs.close()


def test_masked_reset_after_recv_keeps_the_received_observations():
    """A masked reset returns, for the envs it does not reset, their latest observations:
    those of the last `recv`, not of the last lock-step `reset`."""
    envs = envhub.make_vec("gym-cartpole", 3, num_workers=1, autoreset_mode="disabled")
    try:
        first, _ = envs.reset(seed=0)
        first = np.array(first)
        envs.send(np.array([1, 0]), env_ids=[0, 2])
        obs, _, _, _, info = envs.recv()
        received = {int(i): np.array(obs[k]) for k, i in enumerate(info["env_id"])}
        assert sorted(received) == [0, 2]
        merged, _ = envs.reset(options={"reset_mask": np.array([False, True, False])})
        np.testing.assert_array_equal(merged[0], received[0])
        np.testing.assert_array_equal(merged[2], received[2])
        assert not np.array_equal(merged[0], first[0])  # it stepped
    finally:
        envs.close()


def test_step_with_results_pending_is_an_error():
    envs = envhub.make_vec("gym-cartpole", 2, num_workers=1)
    try:
        envs.reset(seed=0)
        envs.send(np.array([0, 1]))
        with pytest.raises(envhub.InvalidStateError, match="recv"):
            envs.step(np.array([0, 1]))
        envs.recv()
        envs.step(np.array([0, 1]))
    finally:
        envs.close()


def test_bad_actions_are_value_errors():
    envs = envhub.make_vec("gym-cartpole", 3, num_workers=1)
    try:
        envs.reset(seed=0)
        with pytest.raises(ValueError, match="env 1") as caught:
            envs.step(np.array([0, 2, 1]))
        assert isinstance(caught.value, envhub.InvalidActionError)
        assert "Discrete(2)" in str(caught.value)
        with pytest.raises(envhub.InvalidActionError, match="shape"):
            envs.step(np.array([0, 1]))
        with pytest.raises(envhub.InvalidActionError, match="integers"):
            envs.step(np.array([0.0, 1.0, 1.0]))
        envs.step(np.array([0, 1, 1], dtype=np.int32))  # any integer dtype
    finally:
        envs.close()
