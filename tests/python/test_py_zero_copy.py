"""Observations are numpy arrays viewing the worker's shared-memory sample: checked by
address (inside a `/dev/shm` mapping of this process, equal to the sample's), read-only, and
still valid and unchanged after later steps, after close, and after the worker is gone. Past
the pool of lendable samples, observations are copies; nothing blocks."""

from __future__ import annotations

import gc
import os
import signal
import threading

import numpy as np
import pytest
from conftest import import_envhub

envhub = import_envhub()


def address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def shm_mappings() -> list[tuple[int, int, str]]:
    """(start, end, path) of this process's mappings of files in /dev/shm."""
    out = []
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 6 and parts[5].startswith("/dev/shm/"):
                lo, hi = (int(x, 16) for x in parts[0].split("-"))
                out.append((lo, hi, parts[5]))
    return out


def in_shared_memory(a: np.ndarray) -> str | None:
    at = address(a)
    return next((path for lo, hi, path in shm_mappings() if lo <= at and at + a.nbytes <= hi), None)


def sample_of(a: np.ndarray):
    """The owner object at the root of an array's bases, if it is envhub's."""
    base = a
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    return base if type(base).__name__ == "SharedSample" else None


@pytest.fixture
def vec():
    envs = envhub.make_vec("gym-cartpole", 16, num_workers=1)
    yield envs
    envs.close()


def test_batch_views_the_shared_memory_sample(vec):
    obs, _ = vec.reset(seed=0)
    sample = sample_of(obs)
    assert sample is not None, "observations are not a view of a shared-memory sample"
    assert address(obs) == sample.address and obs.nbytes == sample.nbytes == 16 * 4 * 4
    path = in_shared_memory(obs)
    assert path is not None and os.environ["ENVHUB_NAMESPACE"] in path, path
    assert not obs.flags.writeable and not obs.flags.owndata
    with pytest.raises(ValueError, match="read-only"):
        obs[0, 0] = 1.0
    with pytest.raises(ValueError):
        obs.setflags(write=True)


def test_kept_arrays_stay_valid_and_unchanged(vec):
    obs, _ = vec.reset(seed=0)
    kept = [obs]
    snapshots = [obs.copy()]
    addresses = {address(obs)}
    for _ in range(3):
        obs, *_ = vec.step(vec.action_space.sample())
        kept.append(obs)
        snapshots.append(obs.copy())
        addresses.add(address(obs))
    assert len(addresses) == 4, "a kept sample was reused"
    for _ in range(200):  # many later steps, with resets inside
        vec.step(vec.action_space.sample())
    for a, s in zip(kept, snapshots, strict=True):
        np.testing.assert_array_equal(a, s)
        assert in_shared_memory(a) is not None


def test_released_samples_are_reused(vec):
    vec.reset(seed=0)
    seen = set()
    for _ in range(50):
        obs, *_ = vec.step(vec.action_space.sample())
        seen.add(address(obs))
        del obs
    # Only the session's last array and the one being received are alive at once: a few
    # samples cycle, memory does not grow.
    assert len(seen) <= 4, len(seen)
    assert vec._session.lent <= 2


def test_past_the_pool_observations_are_copies_and_nothing_blocks(vec):
    obs, _ = vec.reset(seed=0)
    kept = [obs]
    for _ in range(3 * envhub.MAX_LENT_SAMPLES):
        kept.append(vec.step(vec.action_space.sample())[0])
    views = [a for a in kept if sample_of(a) is not None]
    copies = [a for a in kept if sample_of(a) is None]
    assert len(views) == envhub.MAX_LENT_SAMPLES
    assert copies and all(a.flags.owndata and a.flags.writeable for a in copies)
    assert vec._session.lent == envhub.MAX_LENT_SAMPLES
    snapshot = [a.copy() for a in kept]
    del copies, views
    kept = kept[-2:]  # drop the rest: their samples go back to the pool
    gc.collect()
    obs = vec.step(vec.action_space.sample())[0]
    assert sample_of(obs) is not None, "samples were not returned to the pool"
    np.testing.assert_array_equal(kept[-1], snapshot[-1])


def test_arrays_outlive_close_and_the_worker():
    envs = envhub.make_vec("gym-cartpole", 8, num_workers=1)
    obs, _ = envs.reset(seed=3)
    snap = obs.copy()
    pid = envs.worker_pids[0]
    envs.close()
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    del envs
    gc.collect()
    np.testing.assert_array_equal(obs, snap)
    del obs  # releasing the sample after its session is gone must be harmless
    gc.collect()


def test_single_env_observation_is_a_view():
    env = envhub.make("gym-cartpole")
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == (4,) and sample_of(obs) is not None and in_shared_memory(obs)
        first = obs.copy()
        nxt, *_ = env.step(0)
        assert address(nxt) != address(obs)
        np.testing.assert_array_equal(obs, first)
    finally:
        env.close()


def test_several_workers_give_one_fresh_array():
    envs = envhub.make_vec("gym-cartpole", 6, num_workers=2)
    try:
        obs, _ = envs.reset(seed=0)
        assert obs.shape == (6, 4) and obs.flags.c_contiguous
        # Gathered from two samples into one array: a copy the caller owns.
        assert sample_of(obs) is None and obs.flags.writeable
        ref = envhub.make_vec("gym-cartpole", 6, num_workers=1)
        try:
            np.testing.assert_array_equal(ref.reset(seed=0)[0], obs)
        finally:
            ref.close()
    finally:
        envs.close()


def test_arrays_dropped_in_other_threads():
    envs = envhub.make_vec("gym-cartpole", 4, num_workers=1)
    try:
        envs.reset(seed=0)
        batches = [envs.step(envs.action_space.sample())[0] for _ in range(5)]

        def drop():
            batches.clear()
            gc.collect()

        t = threading.Thread(target=drop)
        t.start()
        t.join()
        for _ in range(20):
            obs = envs.step(envs.action_space.sample())[0]
        assert sample_of(obs) is not None
        assert envs._session.lent <= 2
    finally:
        envs.close()
