"""What the Python tests share beyond fixtures: the package or a skip, the repository's root,
and set-ups made once per test run (shared by pytest-xdist's workers).

conftest.py puts this folder (`tests/python/support/`) on `sys.path`, so a test imports
`from harness import import_envhub`; the helper scripts here also run as scripts in other
interpreters (the suites', LeRobot's), by path.
"""

from __future__ import annotations

import fcntl
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[3]
#: This folder: the helper scripts that tests run by path in other interpreters.
SUPPORT = Path(__file__).resolve().parent


def import_envhub():
    """The `envhub` package, or a skip (an error under `ENVHUB_PY_REQUIRED`)."""
    try:
        import envhub
    except ImportError as exc:
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            raise
        pytest.skip(f"the envhub package is not built ({exc}); run `make py-install`")
    return envhub


def mujoco_or_skip(envhub) -> None:
    """A skip when envhub's MuJoCo adapter cannot run here (a worker built without it), or a
    failure under `ENVHUB_MUJOCO_REQUIRED` (as `make py-test` sets, so in CI)."""
    if "mujoco" in envhub.AdapterRegistry().list_available():
        return
    message = "envhub's MuJoCo adapter is not available here"
    if os.environ.get("ENVHUB_MUJOCO_REQUIRED"):
        pytest.fail(f"{message}, and ENVHUB_MUJOCO_REQUIRED is set")
    pytest.skip(message)


def runnable_or_skip(envhub, entry_id: str):
    """An env of `entry_id`, or a skip naming why it cannot run here."""
    try:
        return envhub.make(entry_id)
    except (envhub.AdapterUnavailableError, envhub.NoAdapterError) as exc:
        pytest.skip(f"`{entry_id}` cannot run here: {str(exc).splitlines()[0]}")
    except envhub.MakeError as exc:
        # ManiSkill tasks whose assets are downloaded on first use (from GitHub or Hugging
        # Face): the adapter names the download command; anything else is a real failure.
        if "download_asset" not in str(exc):
            raise
        pytest.skip(f"`{entry_id}` needs assets that are not downloaded here")


def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The temporary folder of this test run, shared by its processes: under pytest-xdist
    each worker's base temporary folder lies in the controller's, which is the run's."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def once_per_run(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], Any]) -> Any:
    """What `make(folder)` returns (JSON), made once per test run: under pytest-xdist the
    workers share it (a lock file in the controller's temporary folder; the first to come
    makes it into `folder`, the others wait and read it), alone the process makes it. For
    set-ups whose result does not depend on the process: a reference run, a built wheel."""
    shared = run_folder(tmp_path_factory)
    folder, result = shared / f"once-{name}", shared / f"once-{name}.json"
    with open(shared / f"once-{name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not result.exists():
                folder.mkdir(exist_ok=True)
                value = make(folder)
                tmp = result.with_suffix(".partial")
                tmp.write_text(json.dumps(value))
                tmp.rename(result)  # a failed `make` leaves nothing: the next test tries again
            return json.loads(result.read_text())
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
