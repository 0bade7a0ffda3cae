"""Results are numpy arrays viewing one shared-memory batch slot that every worker of the
session writes its rows into: checked by address (inside a `/dev/shm` mapping of this process,
equal to the slot owner's), for any number of workers, with no observation bytes copied.
Arrays are writeable (as Gymnasium's) and stay valid and unchanged after later steps, after
close, and after the workers are gone. Past the pool's memory cap, results are copies;
nothing blocks."""

from __future__ import annotations

import gc
import os
import signal
import threading

import numpy as np
import pytest
from harness import import_envhub
from vector_checks import address, in_shared_memory, slot_of

envhub = import_envhub()


@pytest.fixture(params=[1, 2, 3])
def vec(request):
    envs = envhub.make_vec("gym-cartpole", 16, num_workers=request.param)
    yield envs
    envs.close()


def test_one_contiguous_batch_in_shared_memory_for_any_worker_count(vec):
    obs, _ = vec.reset(seed=0)
    for _ in range(50):
        obs, rewards, terminated, truncated, _ = vec.step(vec.action_space.sample())
    slot = slot_of(obs)
    assert slot is not None, "observations are not a view of a shared-memory batch slot"
    assert address(obs) == slot.address and obs.nbytes == slot.nbytes == 16 * 4 * 4
    assert obs.shape == (16, 4) and obs.flags.c_contiguous and not obs.flags.owndata
    path = in_shared_memory(obs)
    assert path is not None and os.environ["ENVHUB_NAMESPACE"] in path and "slots_" in path, path
    for a in (rewards, terminated, truncated):
        assert slot_of(a) is slot and in_shared_memory(a) == path
    assert rewards.dtype == np.float64 and terminated.dtype == np.bool_
    assert vec._session.obs_bytes_copied == 0
    # Writeable, as Gymnasium's arrays are; the session never writes into it again.
    assert obs.flags.writeable
    obs[0, 0] = 123.0
    assert obs[0, 0] == 123.0


def test_same_values_whatever_the_worker_count():
    runs = []
    for workers in (1, 2, 4):
        envs = envhub.make_vec("gym-cartpole", 8, num_workers=workers)
        try:
            obs, _ = envs.reset(seed=5)
            trace = [obs.copy()]
            for t in range(40):
                obs, r, te, tr, _ = envs.step(np.array([(t + i) % 2 for i in range(8)]))
                trace.extend([obs.copy(), r.copy(), te.copy(), tr.copy()])
            runs.append(trace)
        finally:
            envs.close()
    for other in runs[1:]:
        for a, b in zip(runs[0], other, strict=True):
            np.testing.assert_array_equal(a, b)


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
    assert len(addresses) == 4, "a kept slot was reused"
    for _ in range(200):  # many later steps, with resets inside
        vec.step(vec.action_space.sample())
    for a, s in zip(kept, snapshots, strict=True):
        np.testing.assert_array_equal(a, s)
        assert in_shared_memory(a) is not None


def test_released_slots_are_reused(vec):
    vec.reset(seed=0)
    seen = set()
    for _ in range(50):
        obs, *_ = vec.step(vec.action_space.sample())
        seen.add(address(obs))
        del obs
    # Only the last results and the ones being made are alive at once: a few slots cycle,
    # memory does not grow.
    assert len(seen) <= 3, len(seen)
    assert vec._session.slots <= 3


def test_past_the_cap_results_are_copies_and_nothing_blocks():
    slot_bytes = 16 * (4 * 4 + 8 + 3) + 8  # obs, rewards, 3 flag bytes per env, alignment
    envs = envhub.make_vec("gym-cartpole", 16, num_workers=2, pool_bytes=4 * slot_bytes)
    try:
        obs, _ = envs.reset(seed=0)
        kept = [obs]
        for _ in range(12):
            kept.append(envs.step(envs.action_space.sample())[0])
        views = [a for a in kept if slot_of(a) is not None]
        copies = [a for a in kept if slot_of(a) is None]
        assert len(views) == envs._session.slots == 4
        # A copy is a view over memory of its own (one copy out of the slot, no second one
        # into a fresh array), never over a slot.
        assert copies and all(a.flags.writeable for a in copies)
        assert not any(np.shares_memory(c, v) for c in copies for v in views)
        snapshot = [a.copy() for a in kept]
        del copies, views
        kept = kept[-2:]  # drop the rest: their slots go back to the pool
        gc.collect()
        obs = envs.step(envs.action_space.sample())[0]
        assert slot_of(obs) is not None, "slots were not returned to the pool"
        np.testing.assert_array_equal(kept[-1], snapshot[-1])
    finally:
        envs.close()


def test_arrays_outlive_close_and_the_workers():
    envs = envhub.make_vec("gym-cartpole", 8, num_workers=2)
    obs, _ = envs.reset(seed=3)
    snap = obs.copy()
    pids = envs.worker_pids
    namespace = os.environ["ENVHUB_NAMESPACE"]
    envs.close()
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    del envs
    gc.collect()
    np.testing.assert_array_equal(obs, snap)
    # Closing removed the slot's name; the mapping lives on with the array.
    assert not [f for f in os.listdir("/dev/shm") if namespace in f and "slots_" in f]
    del obs  # releasing the slot after its session is gone must be harmless
    gc.collect()


def test_single_env_observation_is_a_view():
    env = envhub.make("gym-cartpole")
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == (4,) and slot_of(obs) is not None and in_shared_memory(obs)
        first = obs.copy()
        nxt, *_ = env.step(0)
        assert address(nxt) != address(obs)
        np.testing.assert_array_equal(obs, first)
    finally:
        env.close()


def test_arrays_dropped_in_other_threads():
    envs = envhub.make_vec("gym-cartpole", 4, num_workers=2)
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
        assert slot_of(obs) is not None
        assert envs._session.slots <= 6
    finally:
        envs.close()


def test_render_works_whatever_the_user_holds():
    """Rendering takes no shared-memory sample a user's arrays could have used up."""
    envs = envhub.make_vec("mujoco-reacher", 2, num_workers=1, render_mode="rgb_array", width=64, height=64)
    try:
        kept = [envs.reset(seed=0)[0]]
        kept += [envs.step(envs.action_space.sample())[0] for _ in range(40)]
        assert all(slot_of(a) is not None for a in kept)
        frames = envs.render()
        assert len(frames) == 2 and frames[0].shape == (64, 64, 3)
    finally:
        envs.close()
