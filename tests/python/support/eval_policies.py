"""The evaluation tests' policies: a file of deterministic policy functions (`policies`, a
fixture: its path), the evaluation's command line run in this interpreter, and a run's
results table to compare runs by."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

POLICY_FILE = textwrap.dedent(
    """\
    import numpy as np

    def act(observations, tasks):
        # A deterministic function of the observation alone.
        return np.stack([np.array([np.tanh(2 * o[0] - o[2])], dtype=np.float32) for o in observations])

    def chunks(observations, tasks):
        # Four actions per answer, from the observation alone.
        return [np.array([[np.tanh(o[0] * k)] for k in range(1, 5)], dtype=np.float32) for o in observations]

    def zeros3(observations, tasks):
        return np.zeros((len(observations), 3), np.float32)
    """
)


@pytest.fixture
def policies(tmp_path):
    path = tmp_path / "policies.py"
    path.write_text(POLICY_FILE)
    return str(path)


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "envhub.evaluation", *args], capture_output=True, text=True, timeout=300, cwd=cwd
    )


def table(results):
    """A run's episodes as comparable rows: what an evaluation promises to repeat."""
    return [
        (e["task"], e["index"], e["init"], e["success"], e["return"], e["length"], e["error"])
        for e in results["episodes"]
    ]
