"""The wheel (`make wheel`) installs with pip into a fresh virtual environment and runs there
as a user would have it, away from the repository: the `envhub` command, the Python API, the
MuJoCo adapters on the `mujoco` wheel's libmujoco, and no binary naming the build machine.

Cost: the fresh environments get the third-party packages (numpy, gymnasium, mujoco, ...) of
the project's `.venv` through a `.pth` file naming a folder of links to them, instead of a
download; `envhub` itself comes only from the wheel (`pip install --no-deps` of the file). The
runs start in an empty folder, with no variable pointing into the repository.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import textwrap
import time
from pathlib import Path

import pytest
from harness import REPO_ROOT, once_per_run

TARGET = REPO_ROOT / "target" / "release"
BINARIES = ("envhub", "envhub-worker", "envhub-worker-mujoco", "envhub-worker-rapier")
SITE = Path(sysconfig.get_paths()["purelib"])
CARGO_HOME = Path(os.environ.get("CARGO_HOME", Path.home() / ".cargo"))


def built() -> bool:
    return all((TARGET / f).is_file() for f in ("lib_envhub.so", *BINARIES))


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    if not built():
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            pytest.fail(f"the release build is missing in {TARGET}; run `make build`")
        pytest.skip("the release build is missing; run `make build`")

    def build(out: Path) -> str:
        start = time.monotonic()
        done = subprocess.run(
            [sys.executable, str(REPO_ROOT / "python" / "build_wheel.py"), "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stdout + done.stderr
        print(f"wheel built in {time.monotonic() - start:.1f} s")
        (path,) = out.glob("envhub-*.whl")
        return str(path)

    # One wheel for the run: the test processes that use it share it.
    return Path(once_per_run(tmp_path_factory, "wheel", build))


def third_party(tmp: Path, without: tuple[str, ...]) -> Path:
    """A folder of links to the project venv's packages, minus envhub's own and `without`."""
    deps = tmp / "deps"
    deps.mkdir()
    for entry in SITE.iterdir():
        name = entry.name.lower()
        if name.startswith(("envhub", "_envhub", "pip", "__editable__")) or name.endswith(".pth"):
            continue
        if name.startswith(without):
            continue
        (deps / entry.name).symlink_to(entry)
    return deps


def install(wheel: Path, tmp: Path, without: tuple[str, ...] = ()) -> Path:
    """A fresh venv in `tmp` with `wheel` installed by pip; returns its folder."""
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    python = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    (site / "third_party.pth").write_text(f"{third_party(tmp, without)}\n")
    # The wheel from a folder of its own, as a download would be.
    local = tmp / "download" / wheel.name
    local.parent.mkdir()
    shutil.copy(wheel, local)
    done = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps", "--no-index", str(local)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return venv


def run(venv: Path, tmp: Path, *argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """`argv` with the venv's `bin` first, from an empty folder, with only basic variables."""
    cwd = tmp / "cwd"
    cwd.mkdir(exist_ok=True)
    env = {
        "PATH": f"{venv / 'bin'}:/usr/local/bin:/usr/bin:/bin",
        "HOME": str(tmp),
        "ENVHUB_NAMESPACE": f"wheel{os.getpid()}_",
    }
    for key, value in env.items():
        assert str(REPO_ROOT) not in value, key
    return subprocess.run(list(argv), cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("wheel-venv")
    start = time.monotonic()
    venv = install(wheel, tmp)
    print(f"installed in {time.monotonic() - start:.1f} s")
    return venv, tmp


def installed_package(venv: Path) -> Path:
    (package,) = venv.glob("lib/python*/site-packages/envhub")
    return package


def test_wheel_contents_and_metadata(wheel):
    import zipfile

    names = zipfile.ZipFile(wheel).namelist()
    for b in BINARIES:
        assert f"envhub/bin/{b}" in names
    assert any(n.startswith("envhub/_envhub.") and n.endswith(".so") for n in names), names
    meta = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "Requires-Dist: gymnasium" in meta and "Requires-Dist: numpy" in meta
    assert 'Requires-Dist: mujoco==3.17.0; extra == "mujoco"' in meta
    points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "envhub = envhub._cli:main" in points


def test_no_binary_names_the_build_machine(venv):
    package = installed_package(venv[0])
    binaries = [package / "bin" / b for b in BINARIES] + list(package.glob("_envhub*.so"))
    needles = {str(REPO_ROOT), str(REPO_ROOT.resolve()), str(CARGO_HOME), str(TARGET), ".build/mujoco"}
    for path in binaries:
        dynamic = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True, check=True).stdout
        assert "RPATH" not in dynamic and "RUNPATH" not in dynamic, f"{path.name}: {dynamic}"
        data = path.read_bytes()
        for needle in needles:
            assert needle.encode() not in data, f"{path.name} contains `{needle}`"
        # Only the MuJoCo worker may need libmujoco: the others start without it.
        needs = "libmujoco" in dynamic
        assert needs == (path.name == "envhub-worker-mujoco"), f"{path.name}: {dynamic}"


def test_cli_runs_mujoco_ant(venv):
    venv, tmp = venv
    done = run(venv, tmp, "envhub", "run", "mujoco-ant", "--num-envs", "4", "--steps", "200")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "mujoco" in done.stdout, done.stdout


def test_cli_runs_a_rapier_task(venv):
    """rapier's worker is a binary of its own in the wheel: `envhub-worker` hands over to it."""
    venv, tmp = venv
    done = run(venv, tmp, "envhub", "run", "rapier-arm-reach", "--num-envs", "2", "--steps", "200")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "rapier-arm-reach: 200 steps" in done.stdout, done.stdout


def test_python_make_vec_steps_mujoco_ant(venv):
    venv, tmp = venv
    script = textwrap.dedent(
        """\
        import envhub, numpy as np
        assert envhub.__file__.startswith(%r), envhub.__file__
        assert "mujoco" in envhub.AdapterRegistry().list_available()
        envs = envhub.make_vec("mujoco-ant", 8)
        obs, _ = envs.reset(seed=0)
        for _ in range(50):
            obs, reward, terminated, truncated, _ = envs.step(envs.action_space.sample())
        assert obs.shape == (8, 105) and np.isfinite(obs).all()
        envs.close()
        # The built-in catalog's own model file (written out of the binary, no source tree).
        env = envhub.make("custom-mjcf-planar-walker")
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.close()
        print("ok")
        """
        % str(venv)
    )
    done = run(venv, tmp, str(venv / "bin" / "python"), "-c", script)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.strip().endswith("ok")


def test_without_the_mujoco_wheel_mujoco_says_how_to_fix_it(wheel, tmp_path):
    venv = install(wheel, tmp_path, without=("mujoco",))
    done = run(venv, tmp_path, "envhub", "adapters", "--all")
    assert done.returncode == 0, done.stdout + done.stderr
    (line,) = [line for line in done.stdout.splitlines() if line.startswith("mujoco ")]
    assert "libmujoco 3.17.0 not found" in line and "pip install 'envhub[mujoco]'" in line, line
    # The router falls back to Gymnasium's own Ant, which needs the `mujoco` package too: an
    # error that says so, not a loader error.
    done = run(venv, tmp_path, "envhub", "run", "mujoco-ant", "--num-envs", "2", "--steps", "10")
    assert done.returncode != 0
    text = done.stdout + done.stderr
    assert "MuJoCo is not installed" in text and "error while loading shared libraries" not in text, text
    # The other native adapters run all the same.
    done = run(venv, tmp_path, "envhub", "run", "gym-cartpole", "--num-envs", "2", "--steps", "100")
    assert done.returncode == 0, done.stdout + done.stderr
