"""Infos of Python-hosted envs made with `envhub.make_vec` (registry entries on the Gymnasium
adapter, user adapters): those that fit the schema learned from the envs' first infos travel
as typed columns in the batch slot, the others as JSON for that env and step. Either way the
vector info is what Gymnasium's `SyncVectorEnv` gives for the same envs, key order, dtypes and
masks included, through every autoreset mode. Native sessions carry no columns."""

from __future__ import annotations

from typing import Any

import envhub
import gymnasium as gym
import numpy as np
import pytest

MODES = {
    "next_step": gym.vector.AutoresetMode.NEXT_STEP,
    "same_step": gym.vector.AutoresetMode.SAME_STEP,
    "disabled": gym.vector.AutoresetMode.DISABLED,
}

REGISTRY = """
environments:
  - {id: hopper-python, name: Hopper, framework: gymnasium, env_id: Hopper-v5, adapter: gymnasium, robot_type: custom, env_type: floor}
  - {id: mixed, name: Mixed infos, framework: mixed_infos, env_id: Mixed-v0, robot_type: custom, env_type: floor}
"""


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("hosted_infos") / "registry.yaml"
    path.write_text(REGISTRY)
    return str(path)


@pytest.fixture(scope="module")
def mixed_adapter() -> None:
    import hosted_adapters

    envhub.AdapterRegistry().register(hosted_adapters.MixedInfoAdapter)


def slot_of(a: np.ndarray) -> Any:
    base = a
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    return base if type(base).__name__ == "SharedSlot" else None


def assert_same_info(got: dict[str, Any], want: dict[str, Any], where: str) -> None:
    assert list(got) == list(want), where
    for key, b in want.items():
        a = got[key]
        if key == "final_info":
            assert_same_info(a, b, f"{where} final_info")
            continue
        if key == "final_obs":
            assert [x is None for x in a] == [x is None for x in b], where
            for x, y in zip(a, b, strict=True):
                if y is not None:
                    np.testing.assert_array_equal(x, y)
            continue
        assert (a.dtype, a.shape) == (b.dtype, b.shape), f"{where} {key}: {a.dtype}{a.shape} != {b.dtype}{b.shape}"
        if b.dtype == object:
            assert list(a) == list(b), f"{where} {key}"
        else:
            np.testing.assert_array_equal(a, b, err_msg=f"{where} {key}")


def run_against_sync(env: Any, ref: Any, mode: str, steps: int, low: float = -1.0) -> int:
    """Steps both with the same actions, resetting ended envs by mask in disabled mode;
    returns how many steps' infos were views of the slot."""
    obs, info = env.reset(seed=5)
    want_obs, want_info = ref.reset(seed=5)
    np.testing.assert_allclose(obs, want_obs, rtol=1e-6)
    assert_same_info(info, want_info, "reset")
    rng = np.random.default_rng(1)
    in_place = 0
    for t in range(steps):
        actions = rng.uniform(low, 1.0, (env.num_envs, *env.single_action_space.shape)).astype(np.float32)
        got = env.step(actions)
        want = ref.step(actions)
        np.testing.assert_allclose(got[0], want[0], rtol=1e-6, atol=1e-9)
        np.testing.assert_array_equal(got[2], want[2])
        assert_same_info(got[4], want[4], f"{mode} step {t}")
        values = [v for k, v in got[4].items() if not k.startswith("_") and isinstance(v, np.ndarray)]
        in_place += bool(values) and all(slot_of(v) is not None for v in values)
        ended = got[2] | got[3]
        if mode == "disabled" and ended.any():
            obs, info = env.reset(options={"reset_mask": ended})
            want_obs, want_info = ref.reset(options={"reset_mask": ended})
            np.testing.assert_allclose(obs, want_obs, rtol=1e-6)
            assert_same_info(info, want_info, f"masked reset after step {t}")
    return in_place


@pytest.mark.parametrize("mode", list(MODES))
def test_hopper_infos_are_typed_columns_and_gymnasiums(registry, mode):
    env = envhub.make_vec("hopper-python", 4, registry=registry, num_workers=2, autoreset_mode=mode)
    ref = gym.make_vec("Hopper-v5", 4, vectorization_mode="sync", vector_kwargs={"autoreset_mode": MODES[mode]})
    try:
        assert env._session.info_row_bytes > 0
        in_place = run_against_sync(env, ref, mode, 300)
        # Every step without an episode's end has its info viewed in place, not parsed.
        assert in_place >= 200, in_place
    finally:
        env.close()
        ref.close()


@pytest.mark.parametrize("mode", list(MODES))
def test_mixed_infos_take_the_json_path_only_where_they_must(registry, mixed_adapter, mode):
    import hosted_adapters

    env = envhub.make_vec("mixed", 6, registry=registry, num_workers=2, autoreset_mode=mode)
    ref = gym.vector.SyncVectorEnv([hosted_adapters.MixedInfoEnv] * 6, autoreset_mode=MODES[mode])
    try:
        in_place = run_against_sync(env, ref, mode, 120)
        assert in_place > 0
    finally:
        env.close()
        ref.close()


@pytest.mark.parametrize("entry", ["gym-cartpole", "mujoco-hopper"])
def test_native_sessions_carry_no_columns(entry):
    env = envhub.make_vec(entry, 2)
    try:
        assert env._session.adapter in ("classic_control", "mujoco")
        assert env._session.info_row_bytes == 0
    finally:
        env.close()
