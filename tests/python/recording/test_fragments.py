"""What the recorder commits is exactly what the envs returned, whatever the vector env
(Gymnasium's own, every autoreset mode, masked resets, a step where one env failed): the
wrapper reads what it needs before the env consumes it. Judged by LeRobot's own loader in its
own interpreter (`support/lerobot_datasets.py`)."""

from __future__ import annotations

import numpy as np
import pytest
from harness import import_envhub
from lerobot_datasets import (
    check_against,
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
)
from recorded_episodes import Episodes

envhub = import_envhub()


def _pendulums(n: int, steps: int, mode: str, asynchronous: bool = False):
    """Gymnasium's own vector env of `n` pendulums whose episodes last exactly `steps` steps."""
    import gymnasium
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

    fns = [lambda: gymnasium.make("Pendulum-v1", max_episode_steps=steps)] * n
    cls = AsyncVectorEnv if asynchronous else SyncVectorEnv
    return cls(fns, autoreset_mode=AutoresetMode(mode))


def _cartpoles(n: int, mode: str, asynchronous: bool):
    """Gymnasium's CartPole: episodes of many lengths (a random policy drops the pole)."""
    import gymnasium
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

    fns = [lambda: gymnasium.make("CartPole-v1", max_episode_steps=30)] * n
    cls = AsyncVectorEnv if asynchronous else SyncVectorEnv
    return cls(fns, autoreset_mode=AutoresetMode(mode))


# Fragments: the wrapper reads what it needs before the env consumes it ------------------------


def test_gymnasium_sync_vector_env_disabled_with_staggered_masked_resets(tmp_path):
    """Three envs whose episodes last exactly 4 steps, `disabled` autoreset, resets masked and
    staggered (Gymnasium's `SyncVectorEnv` pops `reset_mask` from the caller's options): only
    4-step episodes are committed, equal to what the env returned."""
    env = _pendulums(3, 4, "Disabled")
    root = tmp_path / "staggered"
    rec = envhub.RecordEpisodes(env, str(root), video=False)
    rng = np.random.default_rng(0)
    seen = Episodes(3)
    try:
        obs, _ = rec.reset(seed=0)
        for t in range(20):
            if t in (1, 2):  # env t starts over t steps late
                mask = np.arange(3) == t
                obs, _ = rec.reset(options={"reset_mask": mask})
                seen.cut(t)
            actions = rng.uniform(-2, 2, (3, 1)).astype(np.float32)
            nobs, rewards, term, trunc, _ = rec.step(actions)
            for i in range(3):
                seen.add(i, obs[i], actions[i], rewards[i], term[i], trunc[i])
            obs = nobs
            done = term | trunc
            if done.any():
                obs, _ = rec.reset(options={"reset_mask": done.copy()})
    finally:
        rec.close()
    assert [len(ep["action"]) for ep in seen.ended] == [4] * len(seen.ended) and len(seen.ended) >= 12
    assert rec.stats["episodes_written"] == len(seen.ended) and rec.stats["episodes_cut"] == 2
    summary, arrays = load(root)
    assert summary["episode_lengths"] == [4] * len(seen.ended)
    check_against(summary, arrays, seen.ended, "Pendulum-v1")


@pytest.mark.parametrize("asynchronous", [False, True], ids=["sync", "async"])
@pytest.mark.parametrize("mode", ["NextStep", "SameStep", "Disabled"])
def test_every_autoreset_mode_over_gymnasiums_vector_envs(tmp_path, mode, asynchronous):
    """Gymnasium's `SyncVectorEnv` and `AsyncVectorEnv` in each autoreset mode: the dataset
    holds exactly the episodes the env returned."""
    env = _cartpoles(3, mode, asynchronous)
    root = tmp_path / "modes"
    rec = envhub.RecordEpisodes(env, str(root), video=False)
    rng = np.random.default_rng(1)
    seen = Episodes(3)
    try:
        obs, _ = rec.reset(seed=2)
        fresh = np.zeros(3, dtype=bool)
        for _ in range(90):
            actions = rng.integers(0, 2, 3)
            nobs, rewards, term, trunc, _ = rec.step(actions)
            for i in np.flatnonzero(~fresh):
                seen.add(i, obs[i], actions[i], rewards[i], term[i], trunc[i])
            obs = nobs
            done = term | trunc
            if mode == "NextStep":
                fresh = done
            elif mode == "Disabled" and done.any():
                obs, _ = rec.reset(options={"reset_mask": done.copy()})
    finally:
        rec.close()
    assert len(seen.ended) >= 6 and len({len(ep["action"]) for ep in seen.ended}) > 1
    summary, arrays = load(root)
    check_against(summary, arrays, seen.ended, "CartPole-v1")


def test_a_step_where_one_env_failed_keeps_the_others_steps(tmp_path, null_registry):
    """envhub's `EnvFailedError` carries the other envs' results: their steps are recorded,
    the failed env's episode is dropped, and it records again from its reset."""
    env = envhub.make_vec("null-env", 3, num_workers=1, registry=null_registry, max_episode_steps=4, error_after=9)
    # Env 0 steps twice alone first, so it fails (its 9th step) while the others go on.
    env.reset(seed=0)
    for _ in range(2):
        env.send(np.zeros(1, np.int64), env_ids=[0])
        env.recv()
    root = tmp_path / "failed"
    rec = envhub.RecordEpisodes(env, str(root), fps=10, task="nothing")
    seen = Episodes(3)
    failures = 0
    try:
        obs, _ = rec.reset(seed=0)
        fresh = np.zeros(3, dtype=bool)
        for _ in range(9):
            actions = np.zeros(3, np.int64)
            try:
                nobs, rewards, term, trunc, _ = rec.step(actions)
                failed = np.zeros(3, dtype=bool)
            except envhub.EnvFailedError as e:
                failures += 1
                # The others' results: the session's (a Box observation, as the env returns it).
                nobs, rewards, term, trunc = e.results[:4]
                assert nobs.shape == (3, 4) and nobs.dtype == np.float32
                failed = np.isin(np.arange(3), e.env_ids)
            for i in np.flatnonzero(~fresh & ~failed):
                seen.add(i, obs[i], actions[i], rewards[i], term[i], trunc[i])
            obs = nobs
            fresh = term | trunc
            if failed.any():
                for i in np.flatnonzero(failed):
                    seen.cut(i)
                obs, _ = rec.reset(options={"reset_mask": failed})
                fresh &= ~failed
    finally:
        rec.close()
    assert failures == 1 and rec.stats["episodes_dropped"] == 1
    # Episode 1 of every env; episode 2 of envs 1 and 2, the failed step included.
    assert [len(ep["action"]) for ep in seen.ended] == [4] * 5
    summary, arrays = load(root)
    check_against(summary, arrays, seen.ended, "nothing")
