"""Suite environments that installs can share and that stay out of each other's way, on
Meta-World's environment (the cheapest real suite), built into a cache folder of this module's
own with `envhub env sync metaworld`.

- The hub's `PYTHONPATH`, `PYTHONHOME`, `VIRTUAL_ENV` and current folder (a broken `numpy`
  in it) do not reach a suite's worker.
- A suite whose worker cannot start says why, with Python's error and the environment's
  name, not that its framework is unknown.
- A cache made read-only after `sync` (a CI image) still serves sessions.
- Two installs (two copies of the package, their code told apart by a marker) sharing the
  cache: each one's workers run its own code — the package their ready line reports, the
  `_envhub` they map — while the other uses the environment, and after a restart.
- `envhub env run NAME -- ARGS` runs a program as the workers run (this install's `envhub`,
  the suite's packages, none of the caller's Python variables), holding the environment, and
  exits with the program's status.
- `envhub env prune` removes what its rules select, never what is in use.
- `envhub env list --json` shows what each environment's requirements resolved to.

Without uv or PyPI these skip with the reason; under ENVHUB_PYENV_REQUIRED=1 that is a
failure."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml
from harness import REPO_ROOT, import_envhub
from pyenv_cli import RUN_TIMEOUT_S, SYNC_TIMEOUT_S, cli, skip_or_fail

envhub = import_envhub()

from envhub._cli import BINARY  # noqa: E402

ENTRY = "metaworld-reach"


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache folder with Meta-World's environment built in it."""
    if not BINARY.is_file():
        skip_or_fail(f"{BINARY} is not built; run `make py-install`")
    folder = tmp_path_factory.mktemp("shared") / "pyenvs"
    out = cli("env", "sync", "metaworld", cache=folder, timeout=SYNC_TIMEOUT_S)
    if out.returncode != 0:
        skip_or_fail(f"`envhub env sync metaworld` failed: {out.stderr.strip()[-2000:]}")
    return folder


def ran(out: subprocess.CompletedProcess, steps: int = 10) -> None:
    assert out.returncode == 0, out.stderr[-4000:]
    assert f"{ENTRY}: {steps} steps" in out.stdout, out.stdout


def broken_numpy(folder: Path) -> Path:
    """A folder holding a `numpy` that fails at import."""
    (folder / "numpy").mkdir(parents=True)
    (folder / "numpy" / "__init__.py").write_text('raise ImportError("the fake numpy of a test")\n')
    return folder


def test_the_hubs_python_variables_and_folder_do_not_reach_a_suites_worker(cache: Path, tmp_path: Path) -> None:
    shadow = broken_numpy(tmp_path / "shadow")
    out = cli(
        "run",
        ENTRY,
        "--num-envs",
        "2",
        "--steps",
        "10",
        cache=cache,
        cwd=shadow,  # `python -m` would put it first on `sys.path`
        env={
            "PYTHONPATH": str(shadow),
            "PYTHONHOME": str(tmp_path / "no-such-home"),
            "VIRTUAL_ENV": str(tmp_path / "another-venv"),
        },
    )
    ran(out)


def catalog_metaworld() -> dict:
    with open(REPO_ROOT / "configs" / "env_registry.yaml", encoding="utf-8") as f:
        catalog = yaml.safe_load(f)
    entry = next(e for e in catalog["environments"] if e["id"] == ENTRY)
    return {"spec": catalog["python_envs"]["metaworld"], "entry": entry}


def test_a_suite_whose_worker_cannot_start_names_the_error_and_the_environment(cache: Path, tmp_path: Path) -> None:
    shadow = broken_numpy(tmp_path / "declared")
    found = catalog_metaworld()
    # The same requirements (hence the same venv), with a `PYTHONPATH` the environment itself
    # declares: its workers honour it, and cannot import numpy.
    spec = {**found["spec"], "env": {**found["spec"].get("env", {}), "PYTHONPATH": str(shadow)}}
    registry = tmp_path / "registry.yaml"
    registry.write_text(
        yaml.safe_dump({"python_envs": {"metaworld": spec}, "environments": [{**found["entry"], "python_env": "metaworld"}]})
    )
    # The catalog's lock too (`env:` is not part of what it was resolved from).
    shutil.copy(REPO_ROOT / "configs" / "env_registry.lock.yaml", tmp_path / "registry.lock.yaml")
    out = cli("--registry", str(registry), "run", ENTRY, "--num-envs", "2", "--steps", "10", cache=cache)
    assert out.returncode != 0
    assert "python env `metaworld`" in out.stderr, out.stderr
    assert "ImportError: the fake numpy of a test" in out.stderr, out.stderr
    assert "unknown framework" not in out.stderr, out.stderr


def read_only(folder: Path) -> list[str]:
    """A command prefix that runs its command with `folder` read-only: as root, who ignores
    file modes, on a read-only bind mount in a mount namespace of its own; else after
    `chmod -R a-w` (undone by the caller)."""
    if os.geteuid() != 0:
        subprocess.run(["chmod", "-R", "a-w", str(folder)], check=True)
        return []
    probe = subprocess.run(["unshare", "-m", "true"], check=False, capture_output=True)
    if probe.returncode != 0 or not shutil.which("unshare"):
        pytest.skip(f"running as root, and no mount namespace to make the cache read-only in: {probe.stderr!r}")
    script = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" "$0" && exec "$@"'
    return ["unshare", "-m", "sh", "-c", script, str(folder)]


def test_a_read_only_cache_serves_sessions(cache: Path, tmp_path: Path) -> None:
    # Another install too, whose overlay the read-only cache cannot hold (it goes under the
    # temporary folder).
    other = install_copy(tmp_path / "other", "other")
    prefix = read_only(cache)
    try:
        ran(cli("run", ENTRY, "--num-envs", "2", "--steps", "10", cache=cache, prefix=prefix))
        ran(cli("run", ENTRY, "--num-envs", "2", "--steps", "10", cache=cache, prefix=prefix, binary=other / "bin" / "envhub"))
        denied = subprocess.run([*prefix, "touch", str(cache / "probe")], check=False, capture_output=True)
        assert denied.returncode != 0, "the cache was writable: the test proves nothing"
    finally:
        if not prefix:
            subprocess.run(["chmod", "-R", "u+w", str(cache)], check=True)


def install_copy(folder: Path, marker: str) -> Path:
    """A copy of this checkout's `envhub` package in `folder` (hard links where possible: the
    binaries are large), with a marker of its own in its `__init__.py`."""
    source = Path(envhub.__file__).parent

    def link_or_copy(src: str, dst: str) -> None:
        try:
            os.link(src, dst)
        except OSError:
            shutil.copy2(src, dst)

    target = folder / "envhub"
    shutil.copytree(source, target, copy_function=link_or_copy, ignore=shutil.ignore_patterns("__pycache__"))
    init = target / "__init__.py"
    text = init.read_text()
    init.unlink()  # a new file, not the hard-linked original
    init.write_text(f"{text}\n_INSTALL_MARKER = {marker!r}\n")
    return target


CLIENT = textwrap.dedent(
    """\
    import json, os, signal, sys, time
    sys.path.insert(0, sys.argv[1])  # as an editable install's `.pth` would
    import numpy as np
    import envhub

    def children(pid):
        out = []
        for task in os.listdir(f"/proc/{pid}/task"):
            out += open(f"/proc/{pid}/task/{task}/children").read().split()
        return out

    def worker(pid="self"):
        # The living worker (the session's pid list is the first one's): a child, or with
        # warm workers a child of the suite's fork server (a worker itself), so the deepest.
        for child in children(pid):
            if b"envhub.worker" in open(f"/proc/{child}/cmdline", "rb").read():
                return worker(child) or int(child)
        return None

    def report(envs):
        pid = worker()
        with open(f"/proc/{pid}/maps") as f:
            libs = sorted({l.split()[-1] for l in f if l.rstrip().endswith("_envhub.abi3.so")})
        print(json.dumps({"pid": pid, "libs": libs, "marker": envhub._INSTALL_MARKER}), flush=True)

    action = np.zeros((1, 4), dtype=np.float32)
    envs = envhub.make_vec("metaworld-reach", 1, restart_on_crash=True)
    envs.reset(seed=0)
    envs.step(action)
    report(envs)
    sys.stdin.readline()  # the other install has used the environment meanwhile
    os.kill(worker(), signal.SIGKILL)
    envs.step(action)  # restarts the worker
    envs.step(action)
    report(envs)
    envs.close()
    """
)


def start_client(package: Path, cache: Path, log: Path) -> subprocess.Popen:
    """A client process of the install `package` (imported without `PYTHONPATH`, from a
    folder elsewhere, so nothing but envhub's own choice leads its workers there), its hub
    logging what its workers report."""
    env = {
        **os.environ,
        "ENVHUB_PYENV_DIR": str(cache),
        "ENVHUB_LOG": "warn,envhub_hub::launcher=debug,envhub_hub::fork_server=debug",
    }
    env.pop("ENVHUB_PYTHON", None)
    env.pop("PYTHONPATH", None)
    return subprocess.Popen(
        [sys.executable, "-c", CLIENT, str(package.parent)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=log.open("w"),
        text=True,
        env=env,
        cwd=log.parent,
    )


def reported_packages(log: Path) -> list[str]:
    """The packages the workers' ready lines named, as the hub logged them."""
    import re

    return re.findall(r'module: "([^"]+)"', log.read_text())


def test_two_installs_sharing_the_cache_each_run_their_own_code(cache: Path, tmp_path: Path) -> None:
    installs = {m: install_copy(tmp_path / m, m) for m in ("first", "second")}
    logs = {m: tmp_path / f"{m}.log" for m in installs}
    first = start_client(installs["first"], cache, logs["first"])
    try:
        line = first.stdout.readline()
        assert line, logs["first"].read_text()[-3000:]
        before = json.loads(line)
        # The second install opens and closes a session of the same environment meanwhile.
        second = start_client(installs["second"], cache, logs["second"])
        out, _ = second.communicate("\n", timeout=RUN_TIMEOUT_S)
        assert second.returncode == 0, logs["second"].read_text()[-3000:]
        second_reports = [json.loads(line) for line in out.splitlines()]
        out, _ = first.communicate("\n", timeout=RUN_TIMEOUT_S)
        assert first.returncode == 0, logs["first"].read_text()[-3000:]
        after = json.loads(out.splitlines()[-1])
    finally:
        if first.poll() is None:
            first.kill()
    assert after["pid"] != before["pid"], "the worker was not restarted"
    for marker, reports in (("first", [before, after]), ("second", second_reports)):
        package = installs[marker]
        for r in reports:
            assert r["marker"] == marker
            assert r["libs"] == [str(package / "_envhub.abi3.so")], (marker, r)
        told = reported_packages(logs[marker])
        assert len(told) == len(reports) and all(os.path.realpath(t) == str(package) for t in told), (marker, told)
    # Nothing in the venv was re-pointed at an install.
    site = next(cache.glob("metaworld-*/lib/python*/site-packages"))
    assert not (site / "envhub").exists()


RUN_PROBE = """
import json, os, sys, time
import envhub, metaworld
print(json.dumps({"envhub": envhub.__file__, "metaworld": metaworld.__file__, "prefix": sys.prefix,
                  "venv": os.environ.get("VIRTUAL_ENV"), "path": sys.path, "args": sys.argv[1:]}), flush=True)
sys.stdin.readline()
sys.exit(7)
"""


def test_env_run_runs_a_program_as_the_workers_run_holding_the_environment(cache: Path, tmp_path: Path) -> None:
    shadow = broken_numpy(tmp_path / "shadow")
    probe = tmp_path / "probe.py"
    probe.write_text(RUN_PROBE)
    program = subprocess.Popen(
        [str(BINARY), "env", "run", "metaworld", "--", str(probe), "--flag", "x"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "ENVHUB_PYENV_DIR": str(cache), "PYTHONPATH": str(shadow)},
    )
    try:
        line = program.stdout.readline()
        assert line, program.stderr.read()[-3000:]
        seen = json.loads(line)
        # This install's envhub, through its overlay; the suite from the environment's venv.
        assert Path(seen["envhub"]).resolve().parent == Path(envhub.__file__).resolve().parent, seen
        assert ".installs" in seen["envhub"], seen
        assert Path(seen["metaworld"]).is_relative_to(Path(seen["prefix"])), seen
        assert seen["venv"] == seen["prefix"] and str(shadow) not in seen["path"], seen
        assert seen["args"] == ["--flag", "x"], seen
        # The program holds the environment: removing it is refused, naming the program.
        refused = cli("env", "remove", "metaworld", cache=cache)
        assert refused.returncode != 0 and f"pid {program.pid}" in refused.stderr, refused.stderr
        out, err = program.communicate("\n", timeout=RUN_TIMEOUT_S)
    finally:
        if program.poll() is None:
            program.kill()
    assert program.returncode == 7, err[-3000:]  # the program's own status
    unknown = cli("env", "run", "no-such-env", "--", "-c", "pass", cache=cache)
    assert unknown.returncode != 0 and "no python env `no-such-env`" in unknown.stderr, unknown.stderr
    assert "metaworld" in unknown.stderr, unknown.stderr


def test_prune_removes_what_the_rules_select_and_never_what_is_in_use(cache: Path, tmp_path: Path) -> None:
    # Nothing unused for a day: the environment was just used.
    kept = cli("env", "prune", "--unused-days", "1", cache=cache)
    assert kept.returncode == 0 and "0 environment(s) removed" in kept.stdout, kept.stdout + kept.stderr
    # A budget it exceeds selects it; a dry run removes nothing.
    dry = cli("env", "prune", "--max-size", "1M", "--dry-run", cache=cache)
    assert dry.returncode == 0, dry.stderr
    assert "would remove" in dry.stdout and "metaworld-" in dry.stdout, dry.stdout
    assert any(p.name.startswith("metaworld-") for p in cache.iterdir())
    # Sizes count disk once per file: far less than the files' lengths summed twice over.
    listed = json.loads(cli("env", "list", "--json", cache=cache).stdout)
    size = next(r["size_bytes"] for r in listed if r["name"] == "metaworld" and r["in_catalog"])
    assert 10e6 < size < 2e9, size


def test_the_list_shows_what_the_requirements_resolved_to(cache: Path) -> None:
    listed = cli("env", "list", "--json", cache=cache)
    assert listed.returncode == 0, listed.stderr
    row = next(r for r in json.loads(listed.stdout) if r["name"] == "metaworld" and r["in_catalog"])
    resolved = row["resolved"]
    assert "metaworld==3.1.1" in resolved and "mujoco==3.3.0" in resolved, resolved
    # What the unpinned requirements became, with their versions.
    assert any(r.startswith("numpy==") for r in resolved) and any(r.startswith("packaging==") for r in resolved)
    assert resolved == sorted(resolved)
