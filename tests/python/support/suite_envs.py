"""The catalog's suite environments for the tests: the interpreter of a suite's Python
environment, built by envhub if it is not yet (`envhub env sync`), or a skip naming why it
cannot be (a failure under ENVHUB_SUITES_REQUIRED=1)."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

REQUIRED = bool(os.environ.get("ENVHUB_SUITES_REQUIRED"))
# A cold build of the largest suite (robosuite) took under a minute here; the bound is for
# slow networks.
SYNC_TIMEOUT_S = 1200


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_SUITES_REQUIRED is set")
    pytest.skip(reason)


_PYTHONS: dict[str, str | Exception] = {}


def suite_python(name: str) -> str:
    """The interpreter of the catalog's Python environment `name`, built by envhub if it is
    not yet (`envhub env sync`), or a skip naming why it cannot be."""
    if name not in _PYTHONS:
        from envhub._cli import BINARY

        try:
            done = subprocess.run(
                [str(BINARY), "env", "sync", name],
                capture_output=True,
                text=True,
                timeout=SYNC_TIMEOUT_S,
            )
        except (OSError, subprocess.TimeoutExpired) as e:
            _PYTHONS[name] = e
        else:
            found = re.search(rf"^{re.escape(name)}: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
            python = Path(found.group(1)) / "bin" / "python" if found else None
            if done.returncode == 0 and python is not None and python.exists():
                _PYTHONS[name] = str(python)
            else:
                _PYTHONS[name] = RuntimeError(f"exit {done.returncode}: {(done.stderr or done.stdout).strip()[-2000:]}")
    got = _PYTHONS[name]
    if isinstance(got, Exception):
        skip_or_fail(f"the Python environment `{name}` cannot be built here (`envhub env sync {name}`: {got})")
    return str(got)
