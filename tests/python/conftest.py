"""Shared set-up for the Python tests.

The `envhub` tests need the compiled package (`make py-install` builds it into `.venv/`;
`make py-test` does that first). Without it they are skipped, unless `ENVHUB_PY_REQUIRED`
is set (as `make py-test` does), when a missing package is an error.

Every test process gets its own iceoryx2 namespace, so parallel runs never share files:
`pytest{pid}_`, and under pytest-xdist (`-n N`) the controller's prefix plus the worker's
name (`pytest{pid}_gw0_`), so the controller's clean-up at the end also covers its workers'.
The rules that let tests run side by side under `-n N` are in README.md beside this file.

The tests mirror the package (`client/test_env.py` tests `envhub.client.env`); what they
share lives in `support/`, which this file puts on `sys.path` (`from harness import ...`).
"""

from __future__ import annotations

import fcntl
import glob
import os
import re
import sys
import textwrap
from pathlib import Path

import pytest

SUPPORT = Path(__file__).resolve().parent / "support"
sys.path.insert(0, str(SUPPORT))

from harness import REPO_ROOT, run_folder  # noqa: E402

# An xdist worker inherits its controller's environment, and with it the controller's
# namespace: each worker takes its own inside it, never the shared one.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if _WORKER and os.environ.get("ENVHUB_NAMESPACE"):
    NAMESPACE = f"{os.environ['ENVHUB_NAMESPACE']}{_WORKER}_"
    os.environ["ENVHUB_NAMESPACE"] = NAMESPACE
else:
    NAMESPACE = f"pytest{os.getpid()}_"
    os.environ.setdefault("ENVHUB_NAMESPACE", NAMESPACE)
# The tests must not pick up a developer's own registry or daemon.
os.environ.pop("ENVHUB_REGISTRY", None)
os.environ.pop("ENVHUB_HUB", None)
# The interpreters the tests start (hubs' workers in the suites' environments, LeRobot's
# loader, the references) keep the bytecode they compile, as Python does by default: with
# PYTHONDONTWRITEBYTECODE set (as on some machines), each of them compiled torch, robosuite
# or LIBERO from source again, about half of a LeRobot load's CPU and 3 s of a LIBERO worker's
# start. uv installs without bytecode, so the first interpreter writes it, the next ones read
# it (where the folder cannot be written, Python goes on without).
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)


# A registry entry for the `null` adapter: an env that does no work and misbehaves on
# request (`sleep_ms`, `exit_after`, `error_after`), for failure tests. A test adapter: the
# catalog lists it (so the entry routes) only with ENVHUB_TEST_ADAPTERS=1.
os.environ["ENVHUB_TEST_ADAPTERS"] = "1"
NULL_REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: null-env
        name: Null
        framework: envhub
        env_id: Null-v0
        robot_type: custom
        env_type: floor
        task_tags: [nothing]
        description: Does no work.
    """
)


def pytest_configure(config) -> None:
    config.addinivalue_line(
        "markers",
        "serial: the test runs while no other test does (under pytest-xdist): it times how fast "
        "something happens, and tests on the other workers would take the cores it is timed on",
    )
    config.addinivalue_line(
        "markers",
        "slow(first=False): the test takes over a minute on a two-core machine (a `# slow: <why>` "
        "comment says why); pytest-xdist hands these out first, those marked `first` before the others",
    )
    config.addinivalue_line(
        "markers",
        "suite: the test needs a Python environment besides .venv (a suite's, the evaluation's peers', "
        "LeRobot's loader): conftest.py marks it by what it uses; `make check` runs `-m 'not suite and not slow'`",
    )
    # Registered by pytest-xdist too; here so that a run without xdist does not warn.
    config.addinivalue_line("markers", "xdist_group(name): under `--dist loadgroup`, one worker runs the group")


#: What a test module uses when it needs a Python environment besides .venv: the switch that
#: turns its skip (no uv, no suite environment, no LeRobot) into a failure, a helper that runs
#: another interpreter built for the tests, or a venv it makes itself (`python -m venv`).
_USES_A_SUITE = re.compile(
    r"ENVHUB_(SUITES|PYENV|LIBERO|LEROBOT)_REQUIRED"
    r"|\b(suite_runs|eval_peers|lerobot_load|lerobot_envs|lerobot_python)\b"
    r"""|["']-m["'],\s*["']venv["']"""
)


def _suite_entries() -> set[str]:
    """The built-in catalog's entries whose workers run in a Python environment of their own:
    the entry names one, or its framework does (`frameworks:` of the registry file). Empty
    without the built package: then the tests that make them skip anyway."""
    try:
        import envhub
        import yaml

        catalog = yaml.safe_load((REPO_ROOT / "configs" / "env_registry.yaml").read_text())
        own = {name for name, f in (catalog.get("frameworks") or {}).items() if f.get("python_env")}
        registry = envhub.EnvRegistry()
        entries = [registry.get(i) for i in registry.list_ids()]
        return {e.id for e in entries if e.python_env is not None or e.framework in own}
    except Exception:
        return set()


_IMPORTS = re.compile(r"^\s*(?:from|import)\s+(\w+)", re.MULTILINE)


def _uses_a_suite(path: Path, seen: set[Path] | None = None) -> bool:
    """Whether the module at `path`, or a module of `support/` it imports (at any depth),
    uses a suite's environment (`_USES_A_SUITE`)."""
    seen = set() if seen is None else seen
    seen.add(path)
    text = path.read_text()
    if _USES_A_SUITE.search(text):
        return True
    for name in _IMPORTS.findall(text):
        helper = SUPPORT / f"{name}.py"
        if helper.exists() and helper not in seen and _uses_a_suite(helper, seen):
            return True
    return False


def pytest_collection_modifyitems(config, items) -> None:
    """Marks `suite` the tests that need a suite's environment, so that `make check` leaves
    them to `make test`: those of a module that uses one (`_uses_a_suite`), and those
    parametrized with a catalog entry (`entry_id`) that runs in a Python environment of its
    own. Then orders the tests for pytest-xdist (`_order_for_xdist`)."""
    modules: dict[Path, bool] = {}
    entries: set[str] | None = None
    for item in items:
        if item.path not in modules:
            modules[item.path] = _uses_a_suite(item.path)
        entry_id = getattr(getattr(item, "callspec", None), "params", {}).get("entry_id")
        if isinstance(entry_id, str) and entries is None:
            entries = _suite_entries()
        if modules[item.path] or (isinstance(entry_id, str) and entry_id in (entries or ())):
            item.add_marker(pytest.mark.suite)
    _order_for_xdist(config, items)


def _order_for_xdist(config, items) -> None:
    """Under pytest-xdist, the order in which tests are handed out:
    - the `serial` tests last: each waits for the tests running beside it, and at the end
      those are few and short;
    - with `--dist loadgroup` (a test at a time to whichever worker is free), the `slow`
      tests first, so that the short tests fill in around them: a slow test handed out last
      keeps one worker busy while the others sit idle. (`--dist load` hands out long runs
      of consecutive tests at first, which would put the slow ones on one worker.) Those
      marked `slow(first=True)` lead: the longest, which uses no suite's environment, so that
      the two workers do not both start with the same suite's first imports (on a fresh
      machine each compiles LIBERO's bytecode and numba caches: 10 s of CPU where one warm
      start takes 5).
    Every worker sorts alike, as xdist requires. Alone, the tests keep the files' order."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    slow_first = bool(getattr(config.option, "loadgroup", False))  # a worker's `--dist loadgroup`

    def rank(item) -> int:
        if item.get_closest_marker("serial"):
            return 3
        slow = item.get_closest_marker("slow")
        if not slow_first or slow is None:
            return 2
        return 0 if slow.kwargs.get("first") else 1

    items.sort(key=rank)


@pytest.fixture(autouse=True)
def _serial_tests_run_alone(request, tmp_path_factory):
    """Under pytest-xdist, a `serial` test holds a lock file exclusively and every other test
    holds it shared, so a serial test waits for the running tests and runs alone. A turnstile
    lock in front makes the tests that come after a waiting serial test wait behind it.
    Without xdist (one test at a time) this does nothing."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        yield
        return
    shared = run_folder(tmp_path_factory)
    serial = request.node.get_closest_marker("serial") is not None
    with open(shared / "serial.turnstile", "a") as turnstile, open(shared / "serial.lock", "a") as lock:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX if serial else fcntl.LOCK_SH)
        finally:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@pytest.fixture
def null_registry(tmp_path: Path) -> str:
    """A registry file with `null-env`, plus the built-in catalog."""
    path = tmp_path / "null_registry.yaml"
    path.write_text(NULL_REGISTRY)
    return str(path)


def pytest_sessionfinish(session, exitstatus) -> None:
    """Removes what this process's namespace left in shared memory (killed workers)."""
    if os.environ.get("ENVHUB_NAMESPACE") != NAMESPACE:
        return
    for path in glob.glob(f"/dev/shm/{NAMESPACE}*") + glob.glob(f"/dev/shm/iox2_{NAMESPACE}*"):
        try:
            os.remove(path)
        except OSError:
            pass
