"""A hub daemon (`envhub serve`) and a user adapter registered in the client with
`AdapterRegistry().register`: the registration reaches the daemon's routing and the workers
it starts, although the daemon's own environment never had it."""

from __future__ import annotations

import os
import select
import subprocess
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT, import_envhub

envhub = import_envhub()

ENVHUB_BIN = REPO_ROOT / "target" / "release" / "envhub"

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: mysim-echo
        name: My simulator echo
        framework: mysim
        env_id: Echo-v0
        robot_type: custom
        env_type: floor
        kwargs: {gain: 2}
    """
)


def _parent_of(pid: int) -> int:
    stat = Path(f"/proc/{pid}/stat").read_text()
    return int(stat[stat.rindex(")") + 2 :].split()[1])


@pytest.fixture
def daemon(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[subprocess.Popen[str]]:
    """`envhub serve` over a registry with `mysim-echo`, started without any user adapter;
    this process's clients use it (ENVHUB_HUB)."""
    if not ENVHUB_BIN.is_file():
        message = f"{ENVHUB_BIN} is not built; run `make py-install`"
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            pytest.fail(message)
        pytest.skip(message)
    registry = tmp_path / "registry.yaml"
    registry.write_text(REGISTRY)
    socket = tmp_path / "hub.sock"
    env = {k: v for k, v in os.environ.items() if k not in ("ENVHUB_ADAPTERS", "PYTHONPATH")}
    env["ENVHUB_REGISTRY"] = f"@default:{registry}"
    proc = subprocess.Popen(
        [str(ENVHUB_BIN), "serve", "--local-only", "--socket", str(socket)],
        env=env,
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        line = proc.stdout.readline() if ready else ""
        assert "listening on" in line, f"the daemon said {line!r} (exit status {proc.poll()})"
        monkeypatch.setenv("ENVHUB_HUB", str(socket))
        # `register` edits this process's environment: undo it after the test.
        monkeypatch.delenv("ENVHUB_ADAPTERS", raising=False)
        monkeypatch.setenv("PYTHONPATH", os.environ.get("PYTHONPATH", ""))
        yield proc
    finally:
        proc.kill()
        proc.wait(timeout=10)


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
