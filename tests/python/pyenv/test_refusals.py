"""What the suites' environments refuse, naming why and what to do:

- A worker refuses a hub of another worker protocol, naming both.
- `envhub env remove` while a session uses the environment is refused, naming its workers'
  pids; `--force` removes it, and the session's next worker start fails saying it was removed.
- A CPython that reports itself free-threaded (a script wrapping a real one) is not picked; the
  error names `uv python install 3.X`.

Without uv or PyPI these skip with the reason; under ENVHUB_PYENV_REQUIRED=1 that is a
failure."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml
from harness import import_envhub
from pyenv_cli import RUN_TIMEOUT_S, SYNC_TIMEOUT_S, cli, skip_or_fail

envhub = import_envhub()


def test_a_worker_refuses_a_hub_of_another_protocol(tmp_path: Path) -> None:
    package = Path(envhub.__file__).parent
    out = subprocess.run(
        [sys.executable, "-m", "envhub.worker", "describe"],
        check=False,
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(package.parent), "ENVHUB_WORKER_PROTOCOL": "999"},
    )
    assert out.returncode != 0
    own = envhub._envhub.WORKER_PROTOCOL
    assert f"speaks envhub worker protocol {own}" in out.stderr, out.stderr
    assert "the hub that started it speaks 999" in out.stderr and str(package) in out.stderr, out.stderr


SESSION = textwrap.dedent(
    """\
    import json, os, signal, sys
    import numpy as np
    import envhub

    action = np.zeros((1, 4), dtype=np.float32)
    envs = envhub.make_vec("metaworld-reach", 1, restart_on_crash=True)
    envs.reset(seed=0)
    envs.step(action)
    print(json.dumps({"pids": list(envs.worker_pids)}), flush=True)
    sys.stdin.readline()  # the environment is removed meanwhile
    os.kill(envs.worker_pids[0], signal.SIGKILL)
    try:
        envs.step(action)  # the restart needs the environment
        print(json.dumps({"error": None}), flush=True)
    except envhub.EnvHubError as e:
        print(json.dumps({"error": str(e)}), flush=True)
    envs.close()
    """
)


def test_removing_an_environment_in_use_is_refused_unless_forced(tmp_path: Path) -> None:
    own = tmp_path / "pyenvs"  # removed below: not the module's cache
    built = cli("env", "sync", "metaworld", cache=own, timeout=SYNC_TIMEOUT_S)
    if built.returncode != 0:
        skip_or_fail(f"`envhub env sync metaworld` failed: {built.stderr.strip()[-2000:]}")
    session = subprocess.Popen(
        [sys.executable, "-c", SESSION],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "ENVHUB_PYENV_DIR": str(own)},
    )
    try:
        line = session.stdout.readline()
        assert line, session.stderr.read()[-3000:]
        pids = json.loads(line)["pids"]
        refused = cli("env", "remove", "metaworld", cache=own)
        assert refused.returncode != 0
        assert "in use" in refused.stderr and f"pid {pids[0]}" in refused.stderr, refused.stderr
        assert "--force" in refused.stderr, refused.stderr
        assert any(p.name.startswith("metaworld-") and p.is_dir() for p in own.iterdir())
        forced = cli("env", "remove", "--force", "metaworld", cache=own)
        assert forced.returncode == 0, forced.stderr
        assert not any(p.name.startswith("metaworld-") and p.is_dir() for p in own.iterdir())
        out, err = session.communicate("\n", timeout=RUN_TIMEOUT_S)
    finally:
        if session.poll() is None:
            session.kill()
    error = json.loads(out.splitlines()[-1])["error"]
    assert error is not None, "the session restarted a worker without its environment"
    assert "python env `metaworld` was removed while this session used it" in error, error
    assert "envhub env sync metaworld" in error, error
    assert "No such file" not in error and "ENOENT" not in error, error


def real_cpython_not_in_usr_bin() -> Path | None:
    """A pyenv CPython whose minor version `/usr/bin` lacks (so it is the only one of it)."""
    root = Path(os.environ.get("PYENV_ROOT") or Path.home() / ".pyenv")
    for python in sorted(root.glob("versions/3.*/bin/python3.[0-9]*")):
        if python.name.count(".") == 1 and python.name[-1].isdigit() and not Path("/usr/bin", python.name).exists():
            return python
    return None


FREE_THREADED = """\
#!/bin/sh
# A CPython that says it is free-threaded: every answer it gives (uv's question, envhub's)
# claims the GIL is disabled.
"{python}" "$@" | sed -e 's/"gil_disabled": false/"gil_disabled": true/g'
"""


def test_a_free_threaded_python_is_not_picked_and_the_hint_names_the_install_command(tmp_path: Path) -> None:
    real = real_cpython_not_in_usr_bin()
    if real is None:
        pytest.skip("no pyenv CPython whose version /usr/bin lacks")
    minor = real.name.removeprefix("python")
    fake_dir = tmp_path / "bin"
    fake_dir.mkdir()
    fake = fake_dir / real.name
    fake.write_text(FREE_THREADED.format(python=real))
    fake.chmod(0o755)
    registry = tmp_path / "registry.yaml"
    registry.write_text(
        yaml.safe_dump({"python_envs": {"ft": {"python": minor, "requirements": ["packaging"]}}, "environments": []})
    )
    env = {
        # The fake first; no pyenv, no uv-managed Pythons.
        "PATH": f"{fake_dir}:/usr/bin:/bin",
        "UV_PYTHON_INSTALL_DIR": str(tmp_path / "uv-pythons"),
        "ENVHUB_PYTHON_INSTALL": "",
    }
    out = cli("--registry", str(registry), "env", "sync", "ft", cache=tmp_path / "pyenvs", env=env, timeout=SYNC_TIMEOUT_S)
    assert out.returncode != 0, f"built on the free-threaded fake: {out.stdout}"
    assert f"wants CPython {minor}" in out.stderr, out.stderr
    assert f"`uv python install {minor}`" in out.stderr and "ENVHUB_PYTHON_INSTALL=1" in out.stderr, out.stderr
    present = out.stderr.split("present:")[1].splitlines()[0]
    assert str(fake) not in present, out.stderr
