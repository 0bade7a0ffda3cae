"""Vector envs served whole by a Python worker (`EnvAdapter.make_vec`): Gymnasium's own
`CartPoleVectorEnv` checked against itself in-process, autoreset and partial-step refusals,
same_step final observations, and a vector env that raises."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()
gym = pytest.importorskip("gymnasium")

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: cp-vector
        name: CartPole, vectorised inside Gymnasium
        framework: gymnasium
        env_id: CartPole-v1
        adapter: gymnasium
        kwargs: {vectorization_mode: vector_entry_point}
        robot_type: custom
        env_type: floor
      - id: lunar-vector
        name: LunarLander, which has no vector entry point
        framework: gymnasium
        env_id: LunarLander-v3
        adapter: gymnasium
        kwargs: {vectorization_mode: vector_entry_point}
        robot_type: custom
        env_type: floor
      - id: counter-vector
        name: A test vector env
        framework: vec_counter
        env_id: Counter-v0
        robot_type: custom
        env_type: floor
      - id: counter-vector-raising
        name: A test vector env that raises in step
        framework: vec_counter
        env_id: Counter-v0
        kwargs: {raise_in_step: true}
        robot_type: custom
        env_type: floor
    """
)


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("hosted_vector") / "registry.yaml"
    path.write_text(REGISTRY)
    return str(path)


@pytest.fixture(scope="module")
def counter_adapter() -> None:
    import vector_adapters

    envhub.AdapterRegistry().register(vector_adapters.CounterVectorAdapter)


def reference(num_envs: int) -> gym.vector.VectorEnv:
    return gym.make_vec("CartPole-v1", num_envs, vectorization_mode="vector_entry_point")


def assert_same_step(got, want) -> None:
    obs, rewards, terminated, truncated, _ = got
    np.testing.assert_array_equal(obs, want[0])
    np.testing.assert_array_equal(rewards, want[1].astype(np.float64))
    np.testing.assert_array_equal(terminated, want[2])
    np.testing.assert_array_equal(truncated, want[3])


def test_cartpole_vector_env_matches_gymnasium_in_process(registry):
    n, seed = 4, 123
    env = envhub.make_vec("cp-vector", n, num_workers=1, registry=registry)
    ref = reference(n)
    try:
        assert env.max_episode_steps == 500
        obs, _ = env.reset(seed=seed)
        want, _ = ref.reset(seed=seed)
        np.testing.assert_array_equal(obs, want)
        rng = np.random.default_rng(0)
        episodes_ended = 0
        for _ in range(400):
            actions = rng.integers(0, 2, size=n)
            got = env.step(actions)
            assert_same_step(got, ref.step(actions))
            episodes_ended += int(np.sum(got[2] | got[3]))
        assert episodes_ended >= 2 * n, "the run must cross episode ends (next_step autoreset)"
    finally:
        env.close()
        ref.close()


def test_two_workers_each_serve_their_own_vector_env(registry):
    """Worker `w` holds envs `3w .. 3w + 2`, seeded `seed + 3w ...`: Gymnasium's meaning of
    one int seed for its vector env, so each worker equals an in-process vector env."""
    seed = 7
    env = envhub.make_vec("cp-vector", 6, num_workers=2, registry=registry)
    refs = [reference(3), reference(3)]
    try:
        assert env.num_workers == 2
        obs, _ = env.reset(seed=seed)
        want = np.concatenate([r.reset(seed=seed + 3 * w)[0] for w, r in enumerate(refs)])
        np.testing.assert_array_equal(obs, want)
        rng = np.random.default_rng(1)
        for _ in range(200):
            actions = rng.integers(0, 2, size=6)
            steps = [r.step(actions[3 * w : 3 * w + 3]) for w, r in enumerate(refs)]
            want = tuple(np.concatenate([s[k] for s in steps]) for k in range(4))
            assert_same_step(env.step(actions), (*want, {}))
    finally:
        env.close()
        for r in refs:
            r.close()


def test_an_autoreset_mode_the_vector_env_does_not_have_is_refused(registry):
    with pytest.raises(envhub.EnvHubError) as caught:
        envhub.make_vec("cp-vector", 2, num_workers=1, autoreset_mode="same_step", registry=registry)
    text = str(caught.value)
    assert "`next_step`" in text and "`same_step`" in text, text
    assert 'autoreset_mode="next_step"' in text, text


def test_a_partial_step_is_refused_and_a_full_one_still_works(registry):
    env = envhub.make_vec("cp-vector", 4, num_workers=1, registry=registry)
    try:
        env.reset(seed=0)
        env.send(np.array([0, 1]), env_ids=[0, 2])
        with pytest.raises(envhub.EnvFailedError) as caught:
            env.recv()
        text = str(caught.value)
        assert "steps its 4 envs" in text and "together" in text and "step all of them" in text, text
        obs, *_ = env.step(np.zeros(4, np.int64))
        assert obs.shape == (4, 4)
    finally:
        env.close()


def test_a_disabled_session_on_a_next_step_vector_env_is_refused(registry):
    with pytest.raises(envhub.EnvHubError) as caught:
        envhub.make_vec("cp-vector", 2, num_workers=1, autoreset_mode="disabled", registry=registry)
    assert "`disabled`" in str(caught.value), str(caught.value)


def test_bad_vectorization_mode_lists_the_valid_one(registry):
    with pytest.raises(envhub.EnvHubError) as caught:
        envhub.make_vec("cp-vector", 2, num_workers=1, registry=registry, vectorization_mode="sync")
    text = str(caught.value)
    assert "'sync'" in text and "`vector_entry_point`" in text, text


def test_an_id_without_a_vector_entry_point_is_a_clear_error(registry):
    with pytest.raises(envhub.EnvHubError) as caught:
        envhub.make_vec("lunar-vector", 2, num_workers=1, registry=registry)
    text = str(caught.value)
    assert "LunarLander-v3" in text and "no vector entry point" in text and "CartPole-v1" in text, text


def test_same_step_final_observations_and_info_of_a_dict_vector_env(registry, counter_adapter):
    n = 3
    env = envhub.make_vec("counter-vector", n, num_workers=1, autoreset_mode="same_step", registry=registry)
    try:
        obs, info = env.reset(seed=5)
        np.testing.assert_array_equal(obs["t"], np.zeros((n, 1)))
        np.testing.assert_array_equal(info["seed"], [5, 5, 5])  # one int seed for the batch
        actions = np.full((n, 2), 0.5, np.float32)
        obs, rewards, terminated, truncated, info = env.step(actions)
        np.testing.assert_array_equal(obs["t"][:, 0], [1, 1, 1])
        np.testing.assert_array_equal(rewards, [1, 1, 1])
        assert not terminated.any() and not truncated.any()
        np.testing.assert_array_equal(info["t"], [1, 1, 1])
        assert "calls" not in info, "a value for the whole batch is not an env's info"
        assert "final_obs" not in info
        obs, rewards, terminated, _, info = env.step(actions)
        # Env 0 ends after 2 steps and restarts in the same step.
        np.testing.assert_array_equal(terminated, [True, False, False])
        np.testing.assert_array_equal(obs["t"][:, 0], [0, 2, 2])
        np.testing.assert_array_equal(info["_final_obs"], [True, False, False])
        final = info["final_obs"]  # as Gymnasium's: one observation (a dict) per env, else None
        assert final.dtype == object and final[1] is None and final[2] is None
        np.testing.assert_array_equal(final[0]["t"], [2])
        np.testing.assert_allclose(final[0]["sum"], [1.0, 1.0])
        # Envs that did not finish: the vector env's own info, unchanged.
        np.testing.assert_array_equal(info["t"], [2, 2, 2])
    finally:
        env.close()


def test_a_partial_reset_goes_to_the_vector_env_as_reset_mask(registry, counter_adapter):
    env = envhub.make_vec("counter-vector", 3, num_workers=1, autoreset_mode="same_step", registry=registry)
    try:
        env.reset(seed=0)
        env.step(np.zeros((3, 2), np.float32))
        obs, _ = env.reset(options={"reset_mask": np.array([False, True, False])})
        np.testing.assert_array_equal(obs["t"][:, 0], [1, 0, 1])
    finally:
        env.close()


def test_cartpole_ignores_reset_mask_so_a_partial_reset_is_an_error(registry):
    env = envhub.make_vec("cp-vector", 2, num_workers=1, registry=registry)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.EnvFailedError) as caught:
            env.reset(options={"reset_mask": np.array([True, False])})
        assert "ignored `options['reset_mask']`" in str(caught.value), str(caught.value)
    finally:
        env.close()


def test_an_exception_in_the_vector_env_carries_its_traceback(registry, counter_adapter):
    env = envhub.make_vec("counter-vector-raising", 2, num_workers=1, autoreset_mode="same_step", registry=registry)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.EnvFailedError) as caught:
            env.step(np.zeros((2, 2), np.float32))
        text = str(caught.value)
        assert "Counter-v0" in text and "Traceback" in text and "boom: the vector env failed in step" in text, text
    finally:
        env.close()
    # The next session works.
    env = envhub.make_vec("cp-vector", 2, num_workers=1, registry=registry)
    try:
        env.reset(seed=0)
        obs, *_ = env.step(np.array([0, 1]))
        assert obs.shape == (2, 4)
    finally:
        env.close()


def test_a_vector_env_that_keeps_its_actions_reads_them_back_unchanged(registry, counter_adapter):
    """The worker gives the vector env its own copy of each action batch: one it keeps still
    holds those actions after later requests have reused the shared-memory sample."""
    import vector_adapters

    lag = vector_adapters.LAG
    envs = envhub.make_vec("counter-vector", 2, num_workers=1, registry=registry, autoreset_mode="same_step")
    try:
        envs.reset(seed=0)
        sent = []
        for t in range(1, 31):
            actions = np.array([[t / 100, 0.0], [-t / 100, 0.0]], np.float32)
            sent.append(actions.copy())
            *_, info = envs.step(actions)
            if t > lag:
                want = sent[t - 1 - lag][:, 0].astype(np.float64)
                np.testing.assert_array_equal(info["lagged"], want, err_msg=f"step {t}")
    finally:
        envs.close()
