"""Locked suite environments: `envhub env lock` resolves a registry file's environments into
`<registry>.lock.yaml` beside it, and `envhub env sync` (or a session's build) installs exactly
those pins, on a small real environment (gymnasium and what it pulls in) in a registry file and a
cache folder of the test's own.

- `env lock` then `sync` on a clean cache: `uv pip freeze` of the venv is the lock's pins for
  this platform (the worker's own `numpy` among them); a session's on-demand build in another
  clean cache gives the same.
- A registry edit without relocking is refused, naming the environment and `envhub env lock
  NAME`; so is an environment added without relocking.
- A registry file without a lock file resolves as before and `env list --json` says
  `unlocked`; the built-in catalog's environments say `locked`.
- A lock for another platform only is refused, naming this platform and the one it has.
- A declaration's `index_url` reaches uv.

Without uv or PyPI these skip with the reason; under ENVHUB_PYENV_REQUIRED=1 that is a
failure.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from harness import import_envhub

envhub = import_envhub()

from envhub._cli import BINARY  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
TIMEOUT_S = 600
PYTHON = "3.11"
HERE = f"{platform.machine()}-unknown-linux-gnu"
OTHER = "aarch64-unknown-linux-gnu" if platform.machine() == "x86_64" else "x86_64-unknown-linux-gnu"

SPEC = {"python": PYTHON, "requirements": ["gymnasium==1.2.0", "packaging"]}
ENTRY = {
    "id": "cartpole-locked",
    "name": "CartPole in a locked environment",
    "framework": "gymnasium",
    "env_id": "CartPole-v1",
    "adapter": "gymnasium",
    "robot_type": "custom",
    "env_type": "floor",
    "python_env": "tiny",
}


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
    pytest.skip(reason)


def write_registry(folder: Path, specs: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "suites.yaml"
    path.write_text(yaml.safe_dump({"python_envs": specs, "environments": [ENTRY]}))
    return path


def cli(*args: str, registry: Path | None, cache: Path) -> subprocess.CompletedProcess:
    flags = ["--registry", str(registry)] if registry else []
    return subprocess.run(
        [str(BINARY), *flags, *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        env={**os.environ, "ENVHUB_PYENV_DIR": str(cache)},
    )


def listed(registry: Path | None, cache: Path) -> dict[str, dict]:
    out = cli("env", "list", "--json", registry=registry, cache=cache)
    assert out.returncode == 0, out.stderr
    return {r["name"]: r for r in json.loads(out.stdout) if r["in_catalog"]}


def lock(registry: Path, cache: Path, *args: str) -> dict:
    out = cli("env", "lock", "tiny", *args, registry=registry, cache=cache)
    if out.returncode != 0 and ("uv" in out.stderr and "found" in out.stderr or "CPython" in out.stderr):
        skip_or_fail(f"`envhub env lock` cannot run here: {out.stderr.strip()[-1500:]}")
    assert out.returncode == 0, out.stderr[-3000:]
    written = registry.with_name("suites.lock.yaml")
    assert f"wrote {written}" in out.stdout, out.stdout
    return yaml.safe_load(written.read_text())["python_envs"]["tiny"]


def freeze(venv: Path) -> list[str]:
    beside = Path(sys.executable).parent / "uv"
    uv = os.environ.get("ENVHUB_UV") or (str(beside) if beside.is_file() else shutil.which("uv") or "uv")
    out = subprocess.run(
        [uv, "pip", "freeze", "--python", str(venv / "bin" / "python")], capture_output=True, text=True, timeout=60, check=True
    )
    return sorted(line.strip() for line in out.stdout.splitlines() if line.strip())


@pytest.fixture
def registry(tmp_path: Path) -> Path:
    if not BINARY.is_file():
        skip_or_fail(f"{BINARY} is not built; run `make py-install`")
    return write_registry(tmp_path / "registry", {"tiny": SPEC})


def test_lock_then_sync_installs_exactly_the_lock(registry: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    locked = lock(registry, cache)
    assert locked["python"] == PYTHON
    pins = locked["platforms"][HERE]
    names = [p.split("==")[0] for p in pins]
    # The worker's own needs are in the lock, pinned like the suite's.
    assert "numpy" in names and "gymnasium==1.2.0" in pins and "packaging" in names, pins
    assert all("==" in p for p in pins), pins
    assert listed(registry, cache)["tiny"]["lock"] == "locked"

    out = cli("env", "sync", "tiny", registry=registry, cache=cache)
    assert out.returncode == 0, out.stderr[-3000:]
    row = listed(registry, cache)["tiny"]
    assert row["ready"]
    venv = cache / row["folder"]
    assert freeze(venv) == sorted(pins)
    assert row["resolved"] == sorted(pins)

    # A session's on-demand build, in another clean cache, installs the same.
    other = tmp_path / "other-cache"
    ran = cli("run", ENTRY["id"], "--num-envs", "1", "--steps", "5", registry=registry, cache=other)
    assert ran.returncode == 0, ran.stderr[-3000:]
    assert f"{ENTRY['id']}: 5 steps" in ran.stdout, ran.stdout
    assert freeze(other / row["folder"]) == sorted(pins)


def test_a_registry_edit_without_relocking_is_refused(registry: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    lock(registry, cache)
    write_registry(registry.parent, {"tiny": {**SPEC, "requirements": ["gymnasium==1.2.0", "packaging==24.2"]}})
    for args in (["env", "sync", "tiny"], ["run", ENTRY["id"], "--steps", "5"]):
        out = cli(*args, registry=registry, cache=cache)
        assert out.returncode != 0, out.stdout
        assert "python env `tiny`" in out.stderr and "changed since it was locked" in out.stderr, out.stderr
        assert "`envhub env lock tiny`" in out.stderr, out.stderr
    assert listed(registry, cache)["tiny"]["lock"] == "stale"
    assert not list(cache.glob("tiny-*/")), "a stale lock must build nothing"

    # An environment added without relocking.
    write_registry(registry.parent, {"tiny": SPEC, "added": SPEC})
    out = cli("env", "sync", "added", registry=registry, cache=cache)
    assert out.returncode != 0
    assert "python env `added`" in out.stderr and "`envhub env lock added`" in out.stderr, out.stderr
    assert listed(registry, cache)["added"]["lock"] == "not in lock"


def test_an_unlocked_registry_says_unlocked_and_the_catalog_is_locked(registry: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    assert listed(registry, cache)["tiny"]["lock"] == "unlocked"
    builtin = listed(None, cache)
    for name in ("metaworld", "dm_control", "robosuite", "myosuite", "libero"):
        assert builtin[name]["lock"] == "locked", builtin[name]


def test_a_lock_for_another_platform_only_is_refused(registry: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    locked = lock(registry, cache, "--platform", OTHER)
    assert list(locked["platforms"]) == [OTHER]
    out = cli("env", "sync", "tiny", registry=registry, cache=cache)
    assert out.returncode != 0
    assert f"has no pins for this platform, {HERE} (it has {OTHER})" in out.stderr, out.stderr
    assert f"`envhub env lock tiny --platform {HERE}`" in out.stderr, out.stderr
    assert listed(registry, cache)["tiny"]["lock"] == f"no pins for {HERE}"
    # Relocking without `--platform` adds this platform and keeps the other.
    assert sorted(lock(registry, cache)["platforms"]) == sorted([HERE, OTHER])


def test_a_declared_index_reaches_uv(tmp_path: Path) -> None:
    if not BINARY.is_file():
        skip_or_fail(f"{BINARY} is not built; run `make py-install`")
    # Port 9 (discard) on loopback: nothing listens, so uv fails, naming the index it tried.
    index = "http://127.0.0.1:9/simple"
    registry = write_registry(tmp_path / "registry", {"tiny": {**SPEC, "index_url": index}})
    out = cli("env", "lock", "tiny", registry=registry, cache=tmp_path / "cache")
    assert out.returncode != 0
    assert "python env `tiny`" in out.stderr and "127.0.0.1:9" in out.stderr, out.stderr
    write_registry(tmp_path / "registry", {"tiny": {**SPEC, "torch_backend": "CUDA 12"}})
    out = cli("env", "list", registry=registry, cache=tmp_path / "cache")
    assert out.returncode != 0 and "torch_backend: CUDA 12" in out.stderr, out.stderr
