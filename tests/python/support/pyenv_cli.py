"""`envhub` on the command line with a cache folder of the test's own (`ENVHUB_PYENV_DIR`), for
the tests of the suites' Python environments; a skip when something they need is missing (a
failure under ENVHUB_PYENV_REQUIRED=1)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from harness import import_envhub

import_envhub()

from envhub._cli import BINARY  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
# A cold build of Meta-World's environment took seconds here; the bound is for slow networks.
SYNC_TIMEOUT_S = 600
RUN_TIMEOUT_S = 180


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
    pytest.skip(reason)


def cli(
    *args: str,
    cache: Path,
    binary: Path = BINARY,
    env: dict[str, str] | None = None,
    cwd: Path | None = None,
    prefix: list[str] | None = None,
    timeout: float = RUN_TIMEOUT_S,
) -> subprocess.CompletedProcess:
    """`envhub ARGS` with the cache folder `cache`."""
    return subprocess.run(
        [*(prefix or []), str(binary), *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        env={**os.environ, "ENVHUB_PYENV_DIR": str(cache), **(env or {})},
    )
