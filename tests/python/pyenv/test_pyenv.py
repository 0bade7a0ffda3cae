"""Python environments provisioned by the hub (uv, real installs from PyPI), through the hub.

- Gymnasium's CartPole in an environment on a second CPython version runs bit for bit like
  CartPole in-process in that same interpreter, its worker in that interpreter (the stable-ABI
  `_envhub` loads there), beside a session on a third version and a native env.
- Two client processes that need the same environment at once build it once.
- An unresolvable requirement fails that session naming the package with uv's message; other
  sessions keep working.
- With `ENVHUB_PROVISION=explicit` a missing environment is an error with the command that
  builds it.

Without uv, a second CPython or PyPI these skip with the reason; under ENVHUB_PYENV_REQUIRED=1
(as `make test` sets) that is a failure.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from harness import REPO_ROOT, import_envhub

envhub = import_envhub()

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
ENVHUB_BIN = REPO_ROOT / "target" / "release" / "envhub"
# Versions other than the client's, tried in order; the first two present are used.
OTHER_VERSIONS = [v for v in ("3.10", "3.12", "3.13", "3.9") if v != f"{sys.version_info[0]}.{sys.version_info[1]}"]
# A cold build (gymnasium + numpy from PyPI) took under 30 s here; the bound is for slow networks.
SYNC_TIMEOUT_S = 600
STEPS = 300


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
    pytest.skip(reason)


def registry_text(versions: list[str]) -> str:
    envs = "\n".join(
        f"""  py{v.replace(".", "")}:
    python: "{v}"
    requirements: ["gymnasium==1.2.0"]
    env: {{ENVHUB_TEST_MARK: "py{v.replace(".", "")}"}}"""
        for v in versions
    )
    entries = "\n".join(
        f"""  - id: cartpole-py{v.replace(".", "")}
    name: CartPole on Python {v}
    framework: gymnasium
    env_id: CartPole-v1
    adapter: gymnasium
    robot_type: custom
    env_type: floor
    python_env: py{v.replace(".", "")}"""
        for v in versions
    )
    broken_entry = """  - id: cartpole-broken
    name: CartPole in an environment that cannot be built
    framework: gymnasium
    env_id: CartPole-v1
    adapter: gymnasium
    robot_type: custom
    env_type: floor
    python_env: broken"""
    broken_env = '  broken:\n    requirements: ["envhub-no-such-package-zz==1.0"]'
    return f"python_envs:\n{envs}\n{broken_env}\nenvironments:\n{entries}\n{broken_entry}\n"


def cli(*args: str, registry: Path, env: dict[str, str] | None = None, timeout: float = SYNC_TIMEOUT_S):
    return subprocess.run(
        [str(ENVHUB_BIN), "--registry", str(registry), *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


@pytest.fixture(scope="module")
def suites(tmp_path_factory) -> tuple[Path, list[str]]:
    """The registry file and the versions whose environments are built (in the default cache
    folder, as users get them: a rerun finds them ready)."""
    if not ENVHUB_BIN.is_file():
        skip_or_fail(f"{ENVHUB_BIN} is not built; run `make py-install`")
    path = tmp_path_factory.mktemp("pyenv") / "registry.yaml"
    path.write_text(registry_text(OTHER_VERSIONS))
    built = []
    for v in OTHER_VERSIONS:
        if len(built) == 2:
            break
        name = "py" + v.replace(".", "")
        out = cli("env", "sync", name, registry=path)
        if out.returncode == 0:
            built.append(v)
        elif "not on this machine" not in out.stderr:
            skip_or_fail(f"`envhub env sync {name}` failed: {out.stderr.strip()[-2000:]}")
    if len(built) < 2:
        skip_or_fail(f"two CPython versions besides {sys.version_info[:2]} are needed, found {built}")
    path.write_text(registry_text(built))
    return path, built


def worker_interpreters() -> list[str]:
    """The executables of this process's living children (the local hub's workers)."""
    found = []
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        try:
            children = (task / "children").read_text().split()
        except OSError:
            continue
        for pid in children:
            try:
                found.append(os.path.realpath(f"/proc/{pid}/exe"))
            except OSError:
                pass
    return found


def in_process(python: str, seed: int, actions: list[int]) -> dict:
    """CartPole stepped in-process by `python` (the environment's own interpreter)."""
    code = textwrap.dedent(
        """\
        import json, sys
        import gymnasium as gym
        seed, actions = json.loads(sys.argv[1])
        env = gym.make("CartPole-v1")
        obs, _ = env.reset(seed=seed)
        out = {"obs": [obs.tolist()], "rew": [], "term": [], "trunc": [], "version": "%d.%d" % sys.version_info[:2]}
        for a in actions:
            obs, r, term, trunc, _ = env.step(a)
            if term or trunc:
                obs, _ = env.reset()
            out["obs"].append(obs.tolist()); out["rew"].append(float(r))
            out["term"].append(bool(term)); out["trunc"].append(bool(trunc))
        print(json.dumps(out))
        """
    )
    done = subprocess.run(
        [python, "-c", code, json.dumps([seed, actions])], check=False, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def env_python(registry: Path, name: str) -> str:
    """The interpreter of the built environment `name`, as `envhub env list` shows it."""
    rows = json.loads(cli("env", "list", "--json", registry=registry).stdout)
    row = next(r for r in rows if r["name"] == name and r["in_catalog"])
    assert row["ready"], row
    return str(_cache_dir() / row["folder"] / "bin" / "python")


def _cache_dir() -> Path:
    if os.environ.get("ENVHUB_PYENV_DIR"):
        return Path(os.environ["ENVHUB_PYENV_DIR"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "envhub" / "pyenvs"


def test_cartpole_on_other_pythons_side_by_side_bit_for_bit(suites) -> None:
    registry, versions = suites
    rng = np.random.default_rng(7)
    actions = [int(a) for a in rng.integers(0, 2, STEPS)]
    envs = {v: envhub.make(f"cartpole-py{v.replace('.', '')}", registry=str(registry)) for v in versions}
    native = envhub.make("gym-cartpole")
    try:
        exes = worker_interpreters()
        for v in versions:
            assert any(os.path.basename(e) == f"python{v}" for e in exes), (v, exes)
        for v, env in envs.items():
            expect = in_process(env_python(registry, "py" + v.replace(".", "")), 3, actions)
            assert expect["version"] == v
            obs, _ = env.reset(seed=3)
            native.reset(seed=3)
            got = [np.asarray(obs).tolist()]
            rew, term, trunc = [], [], []
            for a in actions:
                obs, r, te, tr, _ = env.step(a)
                native.step(a)
                if te or tr:
                    obs, _ = env.reset()
                got.append(np.asarray(obs).tolist())
                rew.append(float(r))
                term.append(bool(te))
                trunc.append(bool(tr))
            # Bit for bit: float32 observations compared as the same Python floats.
            assert got == expect["obs"] and rew == expect["rew"], v
            assert term == expect["term"] and trunc == expect["trunc"], v
    finally:
        for env in envs.values():
            env.close()
        native.close()


def test_two_clients_needing_one_env_build_it_once(suites, tmp_path) -> None:
    registry, versions = suites
    entry = f"cartpole-py{versions[0].replace('.', '')}"
    fresh = {"ENVHUB_PYENV_DIR": str(tmp_path / "pyenvs")}
    procs = [
        subprocess.Popen(
            [str(ENVHUB_BIN), "--registry", str(registry), "run", entry, "--num-envs", "2", "--steps", "200"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **fresh},
        )
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=SYNC_TIMEOUT_S) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err
        assert "200 steps" in out, out
    stderr = "".join(err for _, err in outs)
    assert stderr.count("building python env") == 1, stderr
    # Beside the venv: the installs' overlays (`.installs`), nothing a build left.
    folders = [p.name for p in (tmp_path / "pyenvs").iterdir() if p.is_dir() and p.name != ".installs"]
    assert len(folders) == 1 and not folders[0].startswith("."), folders


def test_an_unresolvable_requirement_names_it_and_other_sessions_keep_working(suites) -> None:
    registry, versions = suites
    good = envhub.make(f"cartpole-py{versions[0].replace('.', '')}", registry=str(registry))
    try:
        good.reset(seed=0)
        start = time.monotonic()
        with pytest.raises(envhub.EnvHubError) as err:
            envhub.make("cartpole-broken", registry=str(registry))
        message = str(err.value)
        assert "python env `broken`" in message and "`envhub-no-such-package-zz==1.0`" in message, message
        assert "not found in the package registry" in message, message  # uv's own words
        assert time.monotonic() - start < SYNC_TIMEOUT_S
        for _ in range(20):
            obs, *_ = good.step(0)
        assert np.isfinite(obs).all()
    finally:
        good.close()
    rows = json.loads(cli("env", "list", "--json", registry=registry).stdout)
    assert not any(r["name"] == "broken" and r["ready"] for r in rows), rows


def test_explicit_provisioning_says_how_to_build(suites, tmp_path) -> None:
    registry, versions = suites
    name = "py" + versions[0].replace(".", "")
    out = cli(
        "run",
        f"cartpole-{name}",
        "--steps",
        "10",
        registry=registry,
        env={"ENVHUB_PROVISION": "explicit", "ENVHUB_PYENV_DIR": str(tmp_path / "empty")},
        timeout=60,
    )
    assert out.returncode != 0
    assert f"python env `{name}` (for `cartpole-{name}`) is not provisioned" in out.stderr, out.stderr
    assert f"envhub env sync {name}" in out.stderr, out.stderr
    assert not (tmp_path / "empty").exists() or not any((tmp_path / "empty").iterdir())


def test_the_cli_shows_each_entrys_environment(suites) -> None:
    registry, versions = suites
    name = "py" + versions[0].replace(".", "")
    envs = cli("envs", registry=registry, timeout=60)
    assert envs.returncode == 0, envs.stderr
    line = next(line for line in envs.stdout.splitlines() if line.startswith(f"cartpole-{name} "))
    assert f"{name} (ready)" in line, envs.stdout
    assert "broken (not built)" in envs.stdout, envs.stdout
    listed = cli("env", "list", registry=registry, timeout=60)
    assert listed.returncode == 0 and "gymnasium==1.2.0" in listed.stdout, listed.stdout


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(name: str, registry: Path, tmp: Path, *extra: str) -> tuple[subprocess.Popen, str]:
    """An `envhub serve` hub on loopback with its own (empty) cache folder."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {k: v for k, v in os.environ.items() if k not in ("ENVHUB_ADAPTERS", "ENVHUB_CONNECT")}
    env.update(
        ENVHUB_NAMESPACE=f"pyenvhub_{name}_{os.getpid()}_",
        ENVHUB_MULTICAST="0",
        ENVHUB_PYENV_DIR=str(tmp / f"{name}-pyenvs"),
    )
    proc = subprocess.Popen(
        [str(ENVHUB_BIN), "--registry", str(registry), "serve", "--socket", str(tmp / f"{name}.sock")]
        + ["--name", name, "--listen", endpoint, *extra],
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    said = "".join(proc.stdout.readline() for _ in range(3))
    assert "on the network" in said, f"hub {name} said {said!r} (exit status {proc.poll()})"
    return proc, endpoint


def test_a_remote_hub_builds_for_remote_clients_only_with_consent(suites, tmp_path, monkeypatch) -> None:
    registry, versions = suites
    name = "py" + versions[0].replace(".", "")
    entry = f"cartpole-{name}"
    strict, strict_at = serve("pyenvstrict", registry, tmp_path)
    lenient, lenient_at = serve("pyenvlenient", registry, tmp_path, "--allow-provision")
    monkeypatch.setenv("ENVHUB_CONNECT", f"{strict_at},{lenient_at}")
    monkeypatch.setenv("ENVHUB_MULTICAST", "0")
    try:
        with pytest.raises(envhub.EnvHubError) as err:
            envhub.make_vec(entry, 2, hubs=["pyenvstrict"], registry=str(registry))
        message = str(err.value)
        assert f"python env `{name}`" in message and "--allow-provision" in message, message
        assert not (tmp_path / "pyenvstrict-pyenvs").exists() or not any((tmp_path / "pyenvstrict-pyenvs").iterdir())
        env = envhub.make_vec(entry, 2, hubs=["pyenvlenient"], registry=str(registry))
        try:
            obs, _ = env.reset(seed=0)
            for _ in range(20):
                obs, *_ = env.step(np.zeros(2, dtype=np.int64))
            assert obs.shape == (2, 4)
        finally:
            env.close()
        assert any(p.name.startswith(f"{name}-") for p in (tmp_path / "pyenvlenient-pyenvs").iterdir())
    finally:
        for proc in (strict, lenient):
            proc.kill()
            proc.wait(timeout=10)
