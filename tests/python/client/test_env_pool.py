"""EnvPool's asynchronous contract through `envhub.make_vec(..., batch_size=M)`:
`async_reset`, `send(actions, env_id)`, `recv` of exactly the first M envs to finish with
`info["env_id"]` — and each env's trajectory bit for bit the one of a lock-step run, for a
native env, MuJoCo, and a Python-hosted env whose resets take a varying time."""

from __future__ import annotations

import os
import sys
import textwrap

import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip

envhub = import_envhub()
gymnasium = pytest.importorskip("gymnasium")

# A Gymnasium env whose reset sleeps 0-30 ms, drawn from its own random stream: envs come
# back out of order, and the draw is part of the trajectory (a reordering that changed an
# env's stream would show).
SLOW_RESET = textwrap.dedent(
    """\
    import time

    import envhub
    import gymnasium
    import numpy as np


    class SlowReset(gymnasium.Env):
        observation_space = gymnasium.spaces.Box(-1e9, 1e9, (3,), np.float64)
        action_space = gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            delay = float(self.np_random.uniform(0.0, 0.03))
            time.sleep(delay)
            self.x = self.np_random.normal(size=3)
            self.t = 0
            return self.x.copy(), {}

        def step(self, action):
            self.t += 1
            self.x = self.x * 0.9 + float(np.sum(action)) + self.np_random.normal(size=3) * 0.01
            terminated = bool(self.np_random.uniform() < 0.1)
            return self.x.copy(), float(self.x[0]), terminated, self.t >= 12, {"t": self.t, "tag": f"step {self.t}"}


    class SlowResetAdapter(envhub.EnvAdapter):
        name = "slow_reset"
        frameworks = ["slow_reset"]
        requires = ["gymnasium"]
        description = "a test env whose resets take a varying time"

        def make(self, env_id, config):
            limit = config.max_episode_steps
            env = SlowReset()
            return gymnasium.wrappers.TimeLimit(env, limit) if limit else env
    """
)

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: slow-reset
        name: An env whose resets take a varying time
        framework: slow_reset
        env_id: SlowReset-v0
        robot_type: custom
        env_type: floor
    """
)


@pytest.fixture(scope="module")
def slow_registry(tmp_path_factory: pytest.TempPathFactory, monkeypatch_module) -> str:
    folder = tmp_path_factory.mktemp("env_pool")
    (folder / "envhub_slow_reset.py").write_text(SLOW_RESET)
    # The worker inherits PYTHONPATH; this process imports it for nothing.
    path = [str(folder), *filter(None, [os.environ.get("PYTHONPATH")])]
    monkeypatch_module.setenv("PYTHONPATH", ":".join(path))
    sys.path.insert(0, str(folder))
    import envhub_slow_reset

    envhub.AdapterRegistry().register(envhub_slow_reset.SlowResetAdapter)
    registry = folder / "registry.yaml"
    registry.write_text(REGISTRY)
    return str(registry)


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    yield mp
    mp.undo()


def _action(space: gymnasium.Space, env: int, t: int) -> np.ndarray:
    """Env `env`'s action at its step `t`: the same whatever order the envs step in."""
    space.seed((env << 20) + t)
    return np.asarray(space.sample())


def _record(obs, rewards, terminated, truncated, info, k: int) -> tuple:
    # An env's own infos (the slow-reset env's step count, a typed column, and its tag, which
    # travels as JSON) travel with its row.
    t = int(info["t"][k]) if "t" in info and info["_t"][k] else None
    tag = str(info["tag"][k]) if "tag" in info and info["_tag"][k] else None
    return (np.asarray(obs[k]).tobytes(), float(rewards[k]), bool(terminated[k]), bool(truncated[k]), t, tag)


def _lock_step(make, steps: int, seed: int) -> list[list[tuple]]:
    envs = make(None)
    try:
        n = envs.num_envs
        obs, _ = envs.reset(seed=seed)
        out = [[(np.asarray(obs[e]).tobytes(), 0.0, False, False, None, None)] for e in range(n)]
        space = envs.single_action_space
        for t in range(steps):
            actions = np.stack([_action(space, e, t) for e in range(n)])
            obs, rew, term, trunc, info = envs.step(actions)
            for e in range(n):
                out[e].append(_record(obs, rew, term, trunc, info, e))
        return out
    finally:
        envs.close()


def _env_pool(make, m: int, steps: int, seed: int) -> list[list[tuple]]:
    envs = make(m)
    try:
        assert envs.batch_size == m
        n = envs.num_envs
        out: list[list[tuple]] = [[] for _ in range(n)]
        space = envs.single_action_space
        envs.async_reset(seed=seed)
        groups = set()
        while any(len(rows) <= steps for rows in out):
            obs, rew, term, trunc, info = envs.recv()
            ids = info["env_id"]
            assert len(ids) == m and len(set(ids.tolist())) == m, ids
            assert obs.shape[0] == m and rew.shape == (m,)
            groups.add(tuple(ids.tolist()))
            for k, e in enumerate(ids):
                if not out[e]:
                    out[e].append((np.asarray(obs[k]).tobytes(), 0.0, False, False, None, None))  # the reset
                else:
                    out[e].append(_record(obs, rew, term, trunc, info, k))
            actions = np.stack([_action(space, int(e), len(out[e]) - 1) for e in ids])
            envs.send(actions, ids)
        assert len(groups) > 1, "the envs came back in one grouping only"
        return out
    finally:
        envs.close()


def _assert_same(sync, pool, steps: int) -> None:
    for e, (a, b) in enumerate(zip(sync, pool, strict=True)):
        assert a[: steps + 1] == b[: steps + 1], f"env {e} differs"


def test_cartpole_per_env_trajectories_equal_lock_step():
    def make(m):
        return envhub.make_vec("gym-cartpole", 8, num_workers=3, batch_size=m)

    steps = 120
    _assert_same(_lock_step(make, steps, 5), _env_pool(make, 3, steps, 5), steps)


def test_mujoco_per_env_trajectories_equal_lock_step():
    mujoco_or_skip(envhub)

    def make(m):
        return envhub.make_vec("mujoco-hopper", 6, num_workers=2, batch_size=m, max_episode_steps=20)

    steps = 60
    _assert_same(_lock_step(make, steps, 2), _env_pool(make, 3, steps, 2), steps)


def test_python_hosted_env_with_varying_reset_cost(slow_registry):
    def make(m):
        return envhub.make_vec("slow-reset", 6, num_workers=3, batch_size=m, registry=slow_registry)

    steps = 30
    # M = 3 over workers of 2 envs: a worker's answer is split between two `recv`s.
    sync = _lock_step(make, steps, 11)
    assert any(row[4] is not None and row[5] is not None for rows in sync for row in rows), "no env info arrived"
    _assert_same(sync, _env_pool(make, 3, steps, 11), steps)


def test_batch_size_checks_and_refusals():
    with pytest.raises(envhub.InvalidConfigError, match="between 1 and 4"):
        envhub.make_vec("gym-cartpole", 4, num_workers=1, batch_size=5)
    with pytest.raises(envhub.InvalidConfigError, match="integer"):
        envhub.make_vec("gym-cartpole", 4, num_workers=1, batch_size=2.0)
    envs = envhub.make_vec("gym-cartpole", 4, num_workers=2, batch_size=2)
    try:
        envs.async_reset(seed=0)
        _, _, _, _, info = envs.recv()
        ids = info["env_id"]
        envs.send(np.zeros(2, dtype=np.int64), env_id=ids)
        with pytest.raises(envhub.InvalidStateError, match="not received"):
            envs.send(np.zeros(1, dtype=np.int64), env_id=ids[:1])
        with pytest.raises(envhub.InvalidStateError, match="EnvPool mode"):
            envs.step(np.zeros(4, dtype=np.int64))
        # A reset drops what was not received, and lock-step works again.
        obs, _ = envs.reset(seed=0)
        assert obs.shape == (4, 4)
        envs.step(np.zeros(4, dtype=np.int64))
    finally:
        envs.close()
