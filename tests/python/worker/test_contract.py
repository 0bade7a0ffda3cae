"""The worker side's contract (docs/design/architecture.md): `envhub.worker` and `envhub.worker.hosted`
run on the oldest versions envhub supports — CPython 3.9, numpy 1.21, Gymnasium 1.1 — and a
worker process imports no client or integration code.

A Python environment of the catalog with exactly those versions (built with uv from PyPI, as
suites' environments are) serves CartPole to a client on this interpreter; its steps equal
CartPole stepped in that interpreter itself. Without uv, CPython 3.9 or PyPI this skips with
the reason; under ENVHUB_PYENV_REQUIRED=1 (as `make py-test` sets) the skip is a failure.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
ENVHUB_BIN = Path(envhub.__file__).parent / "bin" / "envhub"
OLDEST = {"python": "3.9", "numpy": "1.21.6", "gymnasium": "1.1.1"}
SYNC_TIMEOUT_S = 600

REGISTRY = f"""python_envs:
  oldest:
    python: "{OLDEST["python"]}"
    requirements: ["gymnasium=={OLDEST["gymnasium"]}", "numpy=={OLDEST["numpy"]}"]
environments:
  - id: cartpole-oldest
    name: CartPole on the oldest supported worker side
    framework: gymnasium
    env_id: CartPole-v1
    adapter: gymnasium
    robot_type: custom
    env_type: floor
    python_env: oldest
"""

# What a worker process may not have imported: the client's vector code and the integrations.
CLIENT_SIDE = (
    "envhub.client.env",
    "envhub.client.vector",
    "envhub.client.async_vector",
    "envhub.client.factory",
    "envhub.sb3",
    "envhub.recording",
    "envhub.evaluation",
)


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
    pytest.skip(reason)


def cli(*args: str, registry: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(ENVHUB_BIN), "--registry", str(registry), *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=SYNC_TIMEOUT_S,
    )


@pytest.fixture(scope="module")
def oldest(tmp_path_factory) -> tuple[Path, str]:
    """The registry file and the interpreter of the built `oldest` environment."""
    if not ENVHUB_BIN.is_file():
        skip_or_fail(f"{ENVHUB_BIN} is not built; run `make py-install`")
    registry = tmp_path_factory.mktemp("contract") / "registry.yaml"
    registry.write_text(REGISTRY)
    out = cli("env", "sync", "oldest", registry=registry)
    if out.returncode != 0:
        skip_or_fail(f"`envhub env sync oldest` failed: {out.stderr.strip()[-2000:]}")
    rows = json.loads(cli("env", "list", "--json", registry=registry).stdout)
    row = next(r for r in rows if r["name"] == "oldest" and r["in_catalog"])
    assert row["ready"], row
    base = os.environ.get("ENVHUB_PYENV_DIR") or str(
        Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "envhub" / "pyenvs"
    )
    return registry, str(Path(base) / row["folder"] / "bin" / "python")


def run_in(python: str, code: str) -> str:
    """`code` run by the environment's interpreter with this envhub on its path (a venv holds
    the suite only; the hub puts its own install on a worker's path, as this does)."""
    env = {**os.environ, "PYTHONPATH": str(Path(envhub.__file__).resolve().parent.parent)}
    done = subprocess.run([python, "-c", code], check=False, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_environment_has_the_oldest_versions(oldest) -> None:
    _, python = oldest
    got = json.loads(
        run_in(
            python,
            "import json, sys, numpy, gymnasium; "
            "print(json.dumps([list(sys.version_info[:2]), numpy.__version__, gymnasium.__version__]))",
        )
    )
    assert got == [[3, 9], OLDEST["numpy"], OLDEST["gymnasium"]]


def test_a_worker_process_imports_no_client_code(oldest) -> None:
    _, python = oldest
    out = run_in(
        python,
        "import json, sys, envhub.worker.entry as s; "
        "s.describe(); "
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('envhub'))))",
    )
    loaded = json.loads(out)
    assert "envhub.worker.batch" in loaded
    assert not [m for m in loaded if m.startswith(CLIENT_SIDE)], loaded


def test_the_oldest_worker_serves_cartpole_as_it_steps_in_process(oldest) -> None:
    registry, python = oldest
    actions = [int(a) for a in np.random.default_rng(3).integers(0, 2, size=60)]
    script = (
        "import json, gymnasium as gym, numpy as np\n"
        "env = gym.make('CartPole-v1')\n"
        "obs, _ = env.reset(seed=11)\n"
        "out = [obs.tolist()]\n"
        f"for a in {actions!r}:\n"
        "    obs, r, term, trunc, _ = env.step(a)\n"
        "    out.append(obs.tolist())\n"
        "    if term or trunc:\n"
        "        obs, _ = env.reset()\n"
        "        out.append(obs.tolist())\n"
        "print(json.dumps(out))\n"
    )
    expected = np.array(json.loads(run_in(python, script)), dtype=np.float32)
    env = envhub.make("cartpole-oldest", registry=str(registry))
    try:
        obs, _ = env.reset(seed=11)
        got = [obs.copy()]
        for a in actions:
            obs, _, term, trunc, _ = env.step(a)
            got.append(obs.copy())
            if term or trunc:
                obs, _ = env.reset()
                got.append(obs.copy())
    finally:
        env.close()
    assert np.array_equal(np.array(got), expected)
