"""`VectorEnv.send_reset`: some envs reset alone, with their seeds and options, while the
session's other envs step; `recv` returns their first observations. Each env's trajectory is
the one of a lock-step run that resets the same envs with `reset_mask`, and misuse names
what was wrong."""

from __future__ import annotations

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()


def _actions(env: int, t: int) -> np.ndarray:
    return np.random.default_rng([env, t]).uniform(-2.0, 2.0, size=(1,)).astype(np.float32)


def test_envs_reset_alone_follow_the_masked_reset_trajectories():
    n, first, second = 4, 6, 6
    reseed, mask = [40, 41], np.array([True, True, False, False])
    want: list[list[np.ndarray]] = [[] for _ in range(n)]
    steps = [0] * n
    sync = envhub.make_vec("gym-pendulum", n, num_workers=2)
    try:
        assert sync.worker_envs == [(0, 2), (2, 4)]
        obs, _ = sync.reset(seed=9)
        for e in range(n):
            want[e].append(obs[e].copy())
        for r in range(first + second):
            if r == first:
                obs, _ = sync.reset(seed=[*reseed, None, None], options={"reset_mask": mask})
                for e in range(2):
                    want[e].append(obs[e].copy())
                steps[:2] = [0, 0]
            acts = np.stack([_actions(e, steps[e]) for e in range(n)])
            steps = [s + 1 for s in steps]
            obs, rew, *_ = sync.step(acts)
            for e in range(n):
                want[e].append(np.append(obs[e], rew[e]))
    finally:
        sync.close()

    got: list[list[np.ndarray]] = [[] for _ in range(n)]
    steps = [0] * n
    env = envhub.make_vec("gym-pendulum", n, num_workers=2)
    try:
        obs, _ = env.reset(seed=9)
        for e in range(n):
            got[e].append(obs[e].copy())

        def send(ids: list[int]) -> None:
            env.send(np.stack([_actions(e, steps[e]) for e in ids]), ids)
            for e in ids:
                steps[e] += 1

        def receive(count: int, resets: frozenset[int] = frozenset()) -> None:
            while count:
                obs, rew, term, trunc, info = env.recv()
                for k, e in enumerate(info["env_id"].tolist()):
                    if e in resets:
                        assert rew[k] == 0 and not term[k] and not trunc[k]
                        got[e].append(obs[k].copy())
                    else:
                        got[e].append(np.append(obs[k], rew[k]))
                    count -= 1

        for _ in range(first):
            send([0, 1, 2, 3])
            receive(n)
        env.send_reset([0, 1], seed=reseed)
        steps[:2] = [0, 0]
        send([2, 3])
        receive(n, resets=frozenset({0, 1}))
        for _ in range(second - 1):
            send([0, 1, 2, 3])
            receive(n)
        send([0, 1])
        receive(2)

        # Misuse: an env whose worker has results out, seeds that do not match, a mask.
        send([0, 1])
        with pytest.raises(envhub.InvalidStateError, match="still stepping"):
            env.send_reset([1])
        with pytest.raises(envhub.InvalidConfigError, match="1 seeds for 2 envs"):
            env.send_reset([2, 3], seed=[1])
        with pytest.raises(envhub.InvalidConfigError, match="reset_mask"):
            env.send_reset([2], options={"reset_mask": mask})
        # Ids that are no env of the session (negative, past the end), or repeated: named,
        # with the valid range, by send and send_reset alike.
        for bad in ([-1], [2, 4], [2, 2]):
            why = "must not repeat" if bad == [2, 2] else rf"\[{bad[-1]}\] are not envs of this session; valid: 0 to 3"
            with pytest.raises(envhub.InvalidActionError, match=why):
                env.send_reset(bad)
            with pytest.raises(envhub.InvalidActionError, match=why):
                env.send(np.zeros((len(bad), 1), dtype=np.float32), bad)
    finally:
        env.close()
    for e in range(n):
        assert len(got[e]) == len(want[e])
        for t, (a, b) in enumerate(zip(want[e], got[e], strict=True)):
            np.testing.assert_array_equal(a, b, err_msg=f"env {e}, result {t}")
