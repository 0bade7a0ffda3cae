"""EnvPool's contract on a remote hub from Python: `make_vec(..., hubs=..., batch_size=M,
remote_lanes=K)` hands out exactly M envs per `recv`, and every env's trajectory equals the
lock-step run's here, bit for bit, whatever order the envs come back in.
"""

from __future__ import annotations

import numpy as np
import pytest
from harness import import_envhub
from hub_daemons import two_hubs  # noqa: F401 - the fixture

envhub = import_envhub()


def _actions(env: int, t: int) -> int:
    """Env `env`'s action at its step `t`: the same whatever order envs come back in."""
    return int(np.random.default_rng([env, t]).integers(0, 2))


def _lock_step(vec, n: int, steps: int) -> list[list[np.ndarray]]:
    obs, _ = vec.reset(seed=5)
    rows = [[obs[e].copy()] for e in range(n)]
    for t in range(steps):
        obs, rew, term, trunc, _ = vec.step(np.array([_actions(e, t) for e in range(n)]))
        for e in range(n):
            rows[e].append(np.concatenate([obs[e], [rew[e], term[e], trunc[e]]]))
    return rows


def _env_pool(vec, n: int, m: int, steps: int) -> list[list[np.ndarray]]:
    vec.async_reset(seed=5)
    rows: list[list[np.ndarray]] = [[] for _ in range(n)]
    while any(len(r) <= steps for r in rows):
        obs, rew, term, trunc, info = vec.recv()
        ids = [int(e) for e in info["env_id"]]
        assert len(ids) == m == len(set(ids))
        for k, e in enumerate(ids):
            first = not rows[e]
            rows[e].append(obs[k].copy() if first else np.concatenate([obs[k], [rew[k], term[k], trunc[k]]]))
        vec.send(np.array([_actions(e, len(rows[e]) - 1) for e in ids]), ids)
    return rows


@pytest.mark.parametrize("lanes", [1, 2])
def test_remote_send_recv_trajectories_equal_the_lock_step_run(two_hubs, lanes):
    n, steps = 8, 120
    local = envhub.make_vec("gym-cartpole", n, num_workers=2)
    try:
        reference = _lock_step(local, n, steps)
    finally:
        local.close()
    remote = envhub.make_vec("gym-cartpole", n, num_workers=2, hubs=["pya", "pyb"], batch_size=3, remote_lanes=lanes)
    try:
        assert remote.placement == [("pya", 0, 4), ("pyb", 4, 8)]
        got = _env_pool(remote, n, 3, steps)
    finally:
        remote.close()
    for e in range(n):
        for t in range(steps + 1):
            np.testing.assert_array_equal(got[e][t], reference[e][t], err_msg=f"env {e}, step {t}")


def test_remote_lanes_must_be_a_positive_integer():
    for bad in (0, -1, 1.5, True):
        with pytest.raises(envhub.InvalidConfigError, match="remote_lanes"):
            envhub.make_vec("gym-cartpole", 2, remote_lanes=bad)
