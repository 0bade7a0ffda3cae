"""An envhub env started from a Gymnasium env's state follows it bit for bit: the state goes
through `reset(options={"qpos": ..., "qvel": ...})` as JSON, and every float must arrive as
the same double (a demonstration or a replay needs the exact state)."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip

envhub = import_envhub()


def test_half_cheetah_from_gymnasiums_state_follows_it_bit_for_bit():
    mujoco_or_skip(envhub)
    ref = gymnasium.make("HalfCheetah-v5")
    ours = envhub.make("mujoco-half-cheetah")
    try:
        rng = np.random.default_rng(11)
        ref.reset(seed=3)
        low, high = ref.action_space.low, ref.action_space.high
        data = ref.unwrapped.data
        # States of a random rollout (full doubles, most of them 17 significant digits, where
        # a parser that is not correctly rounded misses now and then): each must arrive whole.
        for k in range(20):
            for _ in range(10):
                ref.step(rng.uniform(low, high).astype(np.float32))
            obs, _ = ours.reset(seed=0, options={"qpos": data.qpos.copy(), "qvel": data.qvel.copy()})
            want = ref.unwrapped._get_obs()
            assert obs.dtype == want.dtype and obs.tobytes() == want.tobytes(), (
                f"state {k} arrived changed: max diff "
                f"{np.max(np.abs(obs - want))} in {np.count_nonzero(obs != want)} values"
            )
        # From the last one, the same actions give the same trajectory.
        for t in range(300):
            action = rng.uniform(low, high).astype(np.float32)
            o1, r1, term1, trunc1, _ = ours.step(action)
            o2, r2, term2, trunc2, _ = ref.step(action)
            assert o1.tobytes() == o2.tobytes(), (
                f"step {t}: observations differ by up to {np.max(np.abs(o1 - o2))}"
            )
            assert r1 == pytest.approx(r2, rel=1e-12, abs=1e-12), f"step {t}"
            assert (term1, trunc1) == (term2, trunc2), f"step {t}"
    finally:
        ours.close()
        ref.close()
