"""Envs on other machines' hubs, from Python: `envhub.hubs()` and `make_vec(..., hubs=...)`.

Hubs are `envhub serve` processes on loopback, each with its own iceoryx2 namespace, multicast
off and explicit endpoints, so nothing shortcuts through this machine's shared memory.
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from harness import import_envhub
from hub_daemons import two_hubs  # noqa: F401 - the fixture

envhub = import_envhub()

def test_hubs_lists_the_live_hubs(two_hubs):
    infos = envhub.hubs()
    assert [h["name"] for h in infos] == ["pya", "pyb"]
    assert all(h["cores"] >= 1 and "classic_control" in h["adapters"] for h in infos)


def test_a_vector_env_over_two_hubs_equals_local_stepping(two_hubs):
    remote = envhub.make_vec("gym-cartpole", 8, hubs=["pya", "pyb"])
    local = envhub.make_vec("gym-cartpole", 8)
    try:
        assert remote.placement == [("pya", 0, 4), ("pyb", 4, 8)]
        assert remote.single_observation_space == local.single_observation_space
        a, _ = remote.reset(seed=3)
        b, _ = local.reset(seed=3)
        np.testing.assert_array_equal(a, b)
        rng = np.random.default_rng(0)
        dones = 0
        for _ in range(300):
            actions = rng.integers(0, 2, size=8)
            ra = remote.step(actions)
            lb = local.step(actions)
            for x, y in zip(ra[:4], lb[:4], strict=True):
                np.testing.assert_array_equal(x, y)
            dones += int(lb[2].sum() + lb[3].sum())
        assert dones > 0
    finally:
        remote.close()
        local.close()


def test_send_and_recv_across_hubs_return_every_env_once(two_hubs):
    env = envhub.make_vec("gym-cartpole", 4, hubs={"pya": 2, "local": 2})
    try:
        env.reset(seed=0)
        env.send(np.zeros(4, dtype=np.int64))
        seen: list[int] = []
        while len(seen) < 4:
            *_, info = env.recv()
            seen.extend(int(i) for i in info["env_id"])
        assert sorted(seen) == [0, 1, 2, 3]
    finally:
        env.close()


def test_a_killed_hub_raises_hub_lost_naming_it(two_hubs):
    """The hub's death is noticed as its liveliness token going away (its TCP links close),
    not at the step timeout, which is set far above any wait a loaded machine causes: a loss
    noticed only when it runs out would say "step timeout". How fast it is noticed is a
    figure of docs/benchmarks.md, not a bound here."""
    a, b = two_hubs
    env = envhub.make_vec("gym-cartpole", 4, hubs=["pya", "pyb"], step_timeout=60.0)
    try:
        env.reset(seed=0)
        os.kill(b.proc.pid, signal.SIGKILL)
        with pytest.raises(envhub.HubLostError) as caught:
            for _ in range(3):  # the hub was idle between steps: the next step fails
                env.step(np.zeros(4, dtype=np.int64))
        assert caught.value.hub == "pyb" and caught.value.envs == "2..4"
        assert "liveliness token went away" in str(caught.value), str(caught.value)
        assert "step timeout" not in str(caught.value), str(caught.value)
    finally:
        env.close()


def test_unknown_hubs_and_bad_placements_are_named(two_hubs):
    with pytest.raises(envhub.UnknownHubError, match="closest: pya"):
        envhub.make_vec("gym-cartpole", 2, hubs=["pyaa"])
    with pytest.raises(envhub.InvalidConfigError, match="add up to 3"):
        envhub.make_vec("gym-cartpole", 2, hubs={"pya": 3})
    with pytest.raises(envhub.InvalidConfigError, match="hub names"):
        envhub.make_vec("gym-cartpole", 2, hubs=[1, 2])
