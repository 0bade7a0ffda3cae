"""LeRobot datasets as LeRobot's own loader reads them, for the recording tests.

The loader runs in its own interpreter (`.venv-lerobot/`, with torch; `make lerobot` builds
it, `ENVHUB_LEROBOT_PYTHON` names another) through `lerobot_load.py`, since its pins (numpy,
pandas, av) are not envhub's. Without it, or without pyarrow / PyAV, the tests skip, unless
`ENVHUB_RECORD_REQUIRED` is set (as `make py-test` does).

Codec tolerance: videos are lossy (x264, CRF 18, 4:2:0 chroma); every decoded frame must be
within a mean absolute difference of 5 levels (of 255) of the rendered one, and a PSNR of
30 dB (measured on Hopper's frames: at most 3.1-4.0 levels, at least 32.5-34 dB).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from harness import REPO_ROOT, SUPPORT

REQUIRED = bool(os.environ.get("ENVHUB_RECORD_REQUIRED"))

MEAN_ABS_TOLERANCE = 5.0
PSNR_TOLERANCE = 30.0


def missing(message: str) -> None:
    if REQUIRED:
        pytest.fail(f"{message}, and ENVHUB_RECORD_REQUIRED is set")
    pytest.skip(message)


@pytest.fixture(autouse=True)
def recording_deps() -> None:
    try:
        import av  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as e:
        missing(f"recording needs pyarrow and PyAV ({e}); `pip install 'envhub[record]'`")


def lerobot_python() -> str:
    path = os.environ.get("ENVHUB_LEROBOT_PYTHON") or str(REPO_ROOT / ".venv-lerobot" / "bin" / "python")
    if not Path(path).exists():
        missing(f"LeRobot's loader is not installed at `{path}` (`make lerobot` makes it)")
    return path


class _Loader:
    """LeRobot's loader (`lerobot_load.py --serve`), one interpreter for all the loads of this
    test process: importing torch and LeRobot costs about 8 s of CPU, a test's dataset well
    under one. Each load is a new `LeRobotDataset` (see `lerobot_load.py`). Started on first
    use, started again if it died; it ends when this process does (its stdin closes)."""

    def __init__(self) -> None:
        import atexit

        self.proc: subprocess.Popen | None = None
        self.log = None
        atexit.register(self.close)

    def close(self) -> None:
        if self.proc is not None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self.proc = None

    def _start(self) -> subprocess.Popen:
        import tempfile

        self.log = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            [lerobot_python(), str(SUPPORT / "lerobot_load.py"), "--serve"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log, text=True)
        return self.proc

    def _stderr(self) -> str:
        self.log.seek(0)
        return self.log.read()[-4000:].decode(errors="replace")

    def load(self, root: Path, out: Path, timeout: float = 600) -> None:
        import select

        proc = self.proc if self.proc is not None and self.proc.poll() is None else self._start()
        try:
            proc.stdin.write(f"{root}\t{out}\n")
            proc.stdin.flush()
        except BrokenPipeError:
            pass  # it died: the read below says so
        ready, _, _ = select.select([proc.stdout], [], [], timeout)
        line = proc.stdout.readline() if ready else ""
        if not line:
            proc.kill()
            proc.wait()
            self.proc = None
            reason = f"no answer in {timeout} s" if not ready else f"it exited ({proc.returncode})"
            raise AssertionError(f"LeRobot's loader failed on {root}: {reason}\n{self._stderr()}")
        answer = json.loads(line)
        assert answer["ok"], f"LeRobot's loader failed on {root}:\n{answer['error'][-4000:]}"


_LOADER = _Loader()


def load(root: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """The dataset at `root` as LeRobot's loader gives it (see `lerobot_load.py`)."""
    out = root.parent / f"{root.name}-loaded.npz"
    _LOADER.load(root, out)
    data = np.load(out, allow_pickle=False)
    return json.loads(str(data["summary"])), {k: data[k] for k in data.files if k != "summary"}


def check_video(decoded: np.ndarray, rendered: np.ndarray) -> None:
    assert decoded.shape == rendered.shape, (decoded.shape, rendered.shape)
    diff = np.abs(decoded.astype(np.float64) - rendered.astype(np.float64))
    for k in range(len(diff)):
        mse = float(np.mean(diff[k] ** 2))
        psnr = float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)
        assert diff[k].mean() <= MEAN_ABS_TOLERANCE and psnr >= PSNR_TOLERANCE, (
            f"frame {k}: mean abs diff {diff[k].mean():.2f}, PSNR {psnr:.1f} dB"
        )


def check_against(summary: dict, arrays: dict[str, np.ndarray], expected: list[dict[str, list]],
                  task: str, video_key: str | None = None, cameras: tuple[str, ...] = ()) -> None:
    """The loaded dataset holds exactly the `expected` episodes: states and actions bit for
    bit, flags and rewards exactly, indices and timestamps as LeRobot defines them, frames
    within the codec tolerance (`video_key`: the video of `expected`'s `frame`s; `cameras`:
    videos of observation images, under their feature names in `expected`)."""
    assert summary["num_episodes"] == len(expected)
    lengths = [len(ep["action"]) for ep in expected]
    assert summary["episode_lengths"] == lengths
    assert summary["num_frames"] == sum(lengths)
    assert set(summary["tasks"]) == {task}
    fps = summary["fps"]
    for key in expected[0]:
        if key == "frame" or key in cameras:
            continue
        want = np.concatenate([np.asarray(ep[key]).reshape(len(ep[key]), -1) for ep in expected])
        got = arrays[f"raw/{key}"].reshape(len(want), -1)
        if key.startswith("observation") or key == "action":
            assert got.dtype == want.dtype, (key, got.dtype, want.dtype)
            assert got.tobytes() == want.tobytes(), f"`{key}` differs from what the session returned"
            # What `ds[i]` gives (a torch tensor: LeRobot converts through Python numbers).
            np.testing.assert_array_equal(arrays[key].reshape(len(want), -1), want.astype(arrays[key].dtype))
        else:
            np.testing.assert_array_equal(got.astype(np.float64), want.astype(np.float64), err_msg=key)
    done = np.concatenate([np.logical_or(ep["next.terminated"], ep["next.truncated"]) for ep in expected])
    np.testing.assert_array_equal(arrays["raw/next.done"], done)
    frame_index = np.concatenate([np.arange(n) for n in lengths])
    np.testing.assert_array_equal(arrays["raw/frame_index"], frame_index)
    np.testing.assert_array_equal(arrays["raw/episode_index"], np.repeat(np.arange(len(lengths)), lengths))
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(sum(lengths)))
    np.testing.assert_allclose(arrays["raw/timestamp"], frame_index / fps, rtol=0, atol=1e-5)
    if video_key is not None:
        rendered = np.concatenate([np.stack(ep["frame"]) for ep in expected])
        check_video(arrays[video_key], rendered)
    for key in cameras:
        check_video(arrays[key], np.concatenate([np.stack(ep[key]) for ep in expected]))


def snapshot(root) -> dict[str, str]:
    """Every folder and file under `root`: folders by name, files by their bytes' hash."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root) + "/"] = "dir"
        for f in filenames:
            path = os.path.join(dirpath, f)
            with open(path, "rb") as fh:
                out[os.path.relpath(path, root)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def dataset_files(root) -> list[str]:
    """The files under `root`, relative to it, sorted."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())
