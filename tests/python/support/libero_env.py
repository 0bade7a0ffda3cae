"""LIBERO's catalog environment for the tests that run LIBERO in-process beside envhub: its
interpreter (`envhub env sync libero`), or a skip with the reason (a failure under
ENVHUB_LIBERO_REQUIRED=1 or ENVHUB_SUITES_REQUIRED=1)."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest
from harness import import_envhub

envhub = import_envhub()

REQUIRED = bool(os.environ.get("ENVHUB_LIBERO_REQUIRED") or os.environ.get("ENVHUB_SUITES_REQUIRED"))

# The environment's interpreter run directly, with this envhub on its path (a venv holds the
# suite only; the hub puts its own install on a worker's path).
WITH_ENVHUB = {**os.environ, "PYTHONPATH": str(Path(envhub.__file__).resolve().parent.parent)}


def libero_python(env: str = "libero", suite: str = "LIBERO") -> str:
    """The interpreter of the catalog environment `env` (`libero`, or LIBERO-PRO's
    `libero_pro`), built if missing, with the `libero` adapter available in it; else a skip
    naming why (`suite` names it in the message)."""
    from envhub._cli import BINARY

    def skip(reason: str) -> None:
        if REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_SUITES_REQUIRED or ENVHUB_LIBERO_REQUIRED is set")
        pytest.skip(reason)

    done = subprocess.run([str(BINARY), "env", "sync", env], capture_output=True, text=True, timeout=1800)
    found = re.search(rf"^{re.escape(env)}: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
    if done.returncode != 0 or not found:
        skip(f"{suite}'s Python environment cannot be built here: {(done.stderr or done.stdout)[-1500:]}")
    python = os.path.join(found.group(1), "bin", "python")
    check = subprocess.run(
        [python, "-c", "from envhub.worker.hosted.libero import main; raise SystemExit(main())"],
        capture_output=True,
        text=True,
        timeout=300,
        env=WITH_ENVHUB,
    )
    if check.returncode != 0:
        skip(f"{suite} is unavailable in its environment: {check.stderr.strip()[-1500:]}")
    return python
