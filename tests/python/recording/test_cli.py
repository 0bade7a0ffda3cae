"""`envhub record` on the command line: a policy's rollouts and a run's video into a dataset,
judged by LeRobot's own loader (`support/lerobot_datasets.py`)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from harness import import_envhub, mujoco_or_skip
from lerobot_datasets import (
    load,
    missing,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
)

envhub = import_envhub()
os.environ.setdefault("MUJOCO_GL", "egl")  # Gymnasium's own MuJoCo rendering in hosted workers


# The command line --------------------------------------------------------------------------


def _cli(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    from envhub._cli import BINARY

    if not BINARY.exists():
        missing(f"the `envhub` binary is not built at `{BINARY}` (`make py-install`)")
    full_env = {**os.environ, "ENVHUB_PYTHON": sys.executable, **(env or {})}
    return subprocess.run([str(BINARY), *args], cwd=cwd, capture_output=True, text=True, timeout=300, env=full_env)


def test_cli_record_with_a_policy(tmp_path):
    (tmp_path / "my_policy.py").write_text(
        "import numpy as np\n\ndef push_left(obs):\n    return np.zeros(len(obs), dtype=np.int64)\n"
    )
    proc = _cli("record", "gym-cartpole", "--episodes", "3", "--num-envs", "2", "--out", "ds", "--no-video",
                "--policy", "my_policy:push_left", cwd=tmp_path, env={"PYTHONPATH": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr
    assert "wrote 3 episodes" in proc.stdout and "3/3 episodes" in proc.stderr
    summary, arrays = load(tmp_path / "ds")
    assert summary["num_episodes"] == 3
    assert (arrays["raw/action"] == 0).all()

    bad = _cli("record", "gym-cartpole", "--out", "ds2", "--policy", "my_policy:nope", cwd=tmp_path,
               env={"PYTHONPATH": str(tmp_path)})
    assert bad.returncode == 2 and "error: the module `my_policy` has no `nope`" in bad.stderr


def test_cli_run_video(tmp_path):
    import av

    mujoco_or_skip(envhub)
    proc = _cli("run", "mujoco-hopper", "--video", "hopper.mp4", "--video-steps", "20", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "wrote 21 frames" in proc.stdout
    with av.open(str(tmp_path / "hopper.mp4")) as video:
        frames = [f.to_ndarray(format="rgb24") for f in video.decode(video=0)]
    assert len(frames) == 21 and frames[0].std() > 0
