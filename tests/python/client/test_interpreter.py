"""The native worker finds Gymnasium's MuJoCo assets through the interpreter envhub runs in,
not through whatever `python3` is first on PATH (which may lack Gymnasium)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

from harness import import_envhub

envhub = import_envhub()


def test_mujoco_assets_come_from_the_clients_interpreter(tmp_path):
    # A `python3` first on PATH that has no Gymnasium.
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "python3").write_text("#!/bin/sh\nexit 1\n")
    (fake / "python3").chmod(0o755)
    # The worker away from the repository's .venv (as in an installed package), so that only
    # the hub can tell it which interpreter to use.
    # (`envhub-worker` hands over to `envhub-worker-mujoco` beside it.)
    worker = tmp_path / "envhub-worker"
    for name in ("envhub-worker", "envhub-worker-mujoco"):
        shutil.copy(Path(envhub.__file__).parent / "bin" / name, tmp_path / name)
    env = {k: v for k, v in os.environ.items() if k != "ENVHUB_PYTHON"}
    env["PATH"] = f"{fake}:{env.get('PATH', '')}"
    env["ENVHUB_WORKER"] = str(worker)
    script = textwrap.dedent(
        """\
        import envhub
        env = envhub.make("mujoco-ant")
        obs, _ = env.reset(seed=0)
        print(obs.shape, env._session.adapter)
        env.close()
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    # Native, not the fallback to Gymnasium's own Ant in a Python worker.
    assert done.stdout.strip() == "(105,) mujoco", done.stdout
