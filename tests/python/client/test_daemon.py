"""A hub daemon (`envhub serve`) and a user adapter registered in the client with
`AdapterRegistry().register`: the registration reaches the daemon's routing and the workers
it starts, although the daemon's own environment never had it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from harness import import_envhub
from hub_daemons import daemon  # noqa: F401 - the `envhub serve` fixture

envhub = import_envhub()

def _parent_of(pid: int) -> int:
    stat = Path(f"/proc/{pid}/stat").read_text()
    return int(stat[stat.rindex(")") + 2 :].split()[1])


def test_adapter_registered_in_the_client_runs_in_the_daemons_workers(daemon):
    import hosted_adapters

    registry = envhub.AdapterRegistry()
    assert "mysim" not in [a["name"] for a in registry.list_all()]
    registry.register(hosted_adapters.MySimAdapter)
    info = registry.get("mysim")
    assert info["available"] and info["host"] == "python", info

    env = envhub.make("mysim-echo", seed=5)
    try:
        assert _parent_of(env.worker_pid) == daemon.pid
        obs, info = env.reset()
        assert info["seed"] == 5 and info["extra"] == repr([("gain", 2)]), info
        obs, reward, terminated, truncated, _ = env.step(np.array([0.25], np.float32))
        np.testing.assert_allclose(obs, [1.0, 0.25])
        assert reward == 1.0 and not terminated and not truncated
    finally:
        env.close()
    assert daemon.poll() is None


def test_an_adapter_that_cannot_be_imported_is_named(daemon, monkeypatch):
    monkeypatch.setenv("ENVHUB_ADAPTERS", "envhub_no_such_module_xyz:Nope")
    # The listing and the error both come from the daemon.
    info = envhub.AdapterRegistry().get("envhub_no_such_module_xyz:Nope")
    assert not info["available"]
    assert "cannot import `envhub_no_such_module_xyz:Nope`" in info["reason"], info
    with pytest.raises(envhub.EnvHubError) as caught:
        envhub.make("mysim-echo")
    assert "cannot import `envhub_no_such_module_xyz:Nope`" in str(caught.value)
    assert daemon.poll() is None


#: Failures that reach the client from the hub: an unknown id, an adapter that cannot run
#: here, an option the env does not take.
FAILING_MAKES = [("mujoco-antt", {}), ("isaac-franka-lift", {}), ("gym-pendulum", {"gravty": 9.8})]

#: The attributes a caller reads off envhub's exceptions.
FIELDS = ("env_id", "suggestions", "adapter", "reason", "hint", "worker", "pid", "envs")


def _make_error(entry_id: str, kwargs: dict) -> Exception:
    try:
        envhub.make(entry_id, **kwargs).close()
    except envhub.EnvHubError as e:
        return e
    raise AssertionError(f"`{entry_id}` was made")


def test_errors_through_the_daemon_are_the_embedded_ones(daemon, monkeypatch):
    """Same class, message and attributes whether the hub is a daemon or in this process."""
    through = [_make_error(i, kw) for i, kw in FAILING_MAKES]
    monkeypatch.delenv("ENVHUB_HUB")
    here = [_make_error(i, kw) for i, kw in FAILING_MAKES]
    for (entry_id, _), a, b in zip(FAILING_MAKES, through, here, strict=True):
        assert type(a) is type(b), f"{entry_id}: {type(a).__name__} through the daemon, {type(b).__name__} here"
        assert str(a) == str(b), entry_id
        assert {f: getattr(a, f, None) for f in FIELDS} == {f: getattr(b, f, None) for f in FIELDS}, entry_id
    unknown, unavailable, bad_option = through
    assert isinstance(unknown, KeyError) and isinstance(unknown, envhub.UnknownEnvError)
    assert unknown.env_id == "mujoco-antt" and "mujoco-ant" in unknown.suggestions
    assert isinstance(unavailable, envhub.AdapterUnavailableError) and unavailable.adapter == "isaac_lab"
    assert isinstance(bad_option, envhub.MakeError) and "gravty" in str(bad_option)
    assert daemon.poll() is None
