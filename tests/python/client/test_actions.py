"""Continuous actions beyond the action space's bounds: by default they reach the env, which
clips them as its Gymnasium original does; `strict_actions=True` refuses them. NaN and
infinities are refused either way, as are discrete actions out of range."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()


def test_beyond_the_bounds_is_clipped_by_the_env_as_in_gymnasium():
    reference = gymnasium.make("Pendulum-v1")
    env = envhub.make("gym-pendulum")
    try:
        want, _ = reference.reset(seed=4)
        got, _ = env.reset(seed=4)
        np.testing.assert_allclose(got, want, rtol=1e-6)
        for torque in [6.0, -30.0, 1.5, 2.5, -1e30]:
            action = np.array([torque], dtype=np.float32)
            want, want_reward, *_ = reference.step(action)
            got, reward, *_ = env.step(action)
            # Bit for bit on glibc; the Rust parity tests hold that. Here: the env clipped.
            np.testing.assert_allclose(got, want, rtol=1e-6)
            assert reward == pytest.approx(want_reward, rel=1e-9)
    finally:
        env.close()
        reference.close()


def test_strict_actions_refuse_beyond_the_bounds():
    env = envhub.make("gym-pendulum", strict_actions=True)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError) as caught:
            env.step(np.array([3.0], dtype=np.float32))
        err = caught.value
        assert isinstance(err, envhub.InvalidActionError)
        assert "`gym-pendulum` env 0" in str(err) and "valid range [-2, 2]" in str(err), err
        assert "hint:" in str(err)
        env.step(np.array([2.0], dtype=np.float32))
    finally:
        env.close()
    envs = envhub.make_vec("gym-pendulum", 2, num_workers=1, strict_actions=True)
    try:
        envs.reset(seed=0)
        with pytest.raises(envhub.InvalidActionError, match="env 1: element 0 = -2.5"):
            envs.step(np.array([[0.0], [-2.5]], dtype=np.float32))
        envs.step(np.array([[0.0], [-2.0]], dtype=np.float32))
    finally:
        envs.close()


@pytest.mark.parametrize("strict", [False, True])
def test_non_finite_actions_are_refused_either_way(strict):
    envs = envhub.make_vec("gym-pendulum", 2, num_workers=1, strict_actions=strict)
    try:
        envs.reset(seed=0)
        for bad in [np.nan, np.inf, -np.inf]:
            with pytest.raises(envhub.InvalidActionError, match="env 1") as caught:
                envs.step(np.array([[0.0], [bad]], dtype=np.float32))
            assert "finite" in str(caught.value), caught.value
        envs.step(np.array([[0.0], [0.0]], dtype=np.float32))
    finally:
        envs.close()


@pytest.mark.parametrize("strict", [False, True])
def test_discrete_out_of_range_is_refused_either_way(strict):
    env = envhub.make("gym-cartpole", strict_actions=strict)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.InvalidActionError, match=r"Discrete\(2\)"):
            env.step(2)
        env.step(1)
    finally:
        env.close()


def test_gymnasium_make_takes_strict_actions():
    env = gymnasium.make("envhub/gym-pendulum", strict_actions=True)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.InvalidActionError):
            env.step(np.array([3.0], dtype=np.float32))
    finally:
        env.close()
    env = gymnasium.make("envhub/gym-pendulum")
    try:
        env.reset(seed=0)
        env.step(np.array([3.0], dtype=np.float32))
    finally:
        env.close()
