"""Recording rollouts into LeRobot datasets, judged by LeRobot's own loader.

Each test steps envhub envs through `envhub.RecordEpisodes`, keeps its own copy of what the
session returned, then loads the dataset with `LeRobotDataset(repo_id, root=DIR)` from the
`lerobot-dataset` package. The loader runs in its own interpreter (`.venv-lerobot/`, with
torch; `make lerobot` builds it, `ENVHUB_LEROBOT_PYTHON` names another) through
`lerobot_load.py`, since its pins (numpy, pandas, av) are not envhub's. Without it, or without
pyarrow / PyAV, the tests skip, unless `ENVHUB_RECORD_REQUIRED` is set (as `make py-test` does).

Codec tolerance: videos are lossy (x264, CRF 18, 4:2:0 chroma); every decoded frame must be
within a mean absolute difference of 5 levels (of 255) of the rendered one, and a PSNR of
30 dB (measured on Hopper's frames: at most 3.1-4.0 levels, at least 32.5-34 dB).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from conftest import REPO_ROOT, import_envhub, mujoco_or_skip
from test_py_remote import two_hubs  # noqa: F401 (a fixture: hubs on loopback)

envhub = import_envhub()
REQUIRED = bool(os.environ.get("ENVHUB_RECORD_REQUIRED"))
os.environ.setdefault("MUJOCO_GL", "egl")  # Gymnasium's own MuJoCo rendering in hosted workers

MEAN_ABS_TOLERANCE = 5.0
PSNR_TOLERANCE = 30.0


def _missing(message: str) -> None:
    if REQUIRED:
        pytest.fail(f"{message}, and ENVHUB_RECORD_REQUIRED is set")
    pytest.skip(message)


@pytest.fixture(autouse=True)
def _recording_deps() -> None:
    try:
        import av  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as e:
        _missing(f"recording needs pyarrow and PyAV ({e}); `pip install 'envhub[record]'`")


def lerobot_python() -> str:
    path = os.environ.get("ENVHUB_LEROBOT_PYTHON") or str(REPO_ROOT / ".venv-lerobot" / "bin" / "python")
    if not Path(path).exists():
        _missing(f"LeRobot's loader is not installed at `{path}` (`make lerobot` makes it)")
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
            [lerobot_python(), str(REPO_ROOT / "tests" / "python" / "lerobot_load.py"), "--serve"],
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


def _leaf(obs, path: tuple[str, ...], i: int) -> np.ndarray:
    for key in path:
        obs = obs[key]
    return np.array(obs[i], copy=True)


class FrameTap(gymnasium.vector.VectorWrapper):
    """Between an env and its recorder: keeps what each `render()` of the env returned, and
    the env's calls in order, so that a test gets the frame the env rendered right after each
    reset and step (the frame of that observation) without rendering it a second time."""

    def __init__(self, env) -> None:
        super().__init__(env)
        self.calls: list[str] = []
        self.shown: list[np.ndarray] = []

    def reset(self, **kwargs):
        self.calls.append("reset")
        return self.env.reset(**kwargs)

    def step(self, actions):
        self.calls.append("step")
        return self.env.step(actions)

    def render(self):
        frames = self.env.render()
        self.calls.append("render")
        self.shown = [np.array(f, copy=True) for f in frames]
        return frames

    def after(self, call: str) -> list[np.ndarray]:
        """The frames rendered after `call`, which must be the env's last calls: `call`, then
        one `render()`."""
        assert self.calls == [call, "render"], f"the recorder called {self.calls} for one {call}"
        self.calls = []
        return self.shown


def drive(rec, steps: int, act, *, seed: int, same_step: bool = False, frames: FrameTap | None = None,
          paths: dict[str, tuple[str, ...]] | None = None) -> list[dict[str, list]]:
    """Steps `rec` and returns the episodes that ended, in the order they ended (by step, then
    env), each as lists of what the session returned: per frame the observation leaves
    (`paths`: feature -> keys into the observation), the action, reward, flags and (with
    `frames`, the tap under `rec`) the frame the env rendered for that observation."""
    paths = paths or {"observation.state": ()}
    obs, _ = rec.reset(seed=seed)
    n = rec.num_envs
    shown = frames.after("reset") if frames else None
    current: list[dict[str, list]] = [{} for _ in range(n)]
    fresh = np.zeros(n, dtype=bool)
    ended = []
    for _ in range(steps):
        actions = act(obs)
        kept_actions = np.array(actions, copy=True)
        nobs, rewards, term, trunc, _ = rec.step(actions)
        for i in range(n):
            if fresh[i]:
                continue  # the autoreset step
            ep = current[i]
            for name, path in paths.items():
                ep.setdefault(name, []).append(_leaf(obs, path, i))
            ep.setdefault("action", []).append(kept_actions[i])
            ep.setdefault("next.reward", []).append(float(rewards[i]))
            ep.setdefault("next.terminated", []).append(bool(term[i]))
            ep.setdefault("next.truncated", []).append(bool(trunc[i]))
            if frames:
                ep.setdefault("frame", []).append(np.array(shown[i], copy=True))
            if term[i] or trunc[i]:
                ended.append(ep)
                current[i] = {}
        done = np.logical_or(term, trunc)
        fresh = np.zeros(n, dtype=bool) if same_step else done
        obs = nobs
        shown = frames.after("step") if frames else None
    return ended


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


# Native, Python-hosted, Dict with a camera -------------------------------------------------


# slow: 60 steps of three Hoppers, each step rendered (MuJoCo offscreen through Mesa's software
# EGL here, about 40 ms a frame); the 60 steps give the six episodes of different lengths the
# test checks.
@pytest.mark.slow
def test_native_mujoco_with_render_frames(tmp_path):
    """A native MuJoCo env (Hopper, three envs, `next_step` autoreset) with `rgb_array`
    frames: episodes of different lengths, states and actions bit for bit, the video within
    the codec tolerance."""
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 3, num_workers=1, render_mode="rgb_array",
                          max_episode_steps=25, width=64, height=48)
    root = tmp_path / "hopper"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root), commit_every=0.05)
    rng = np.random.default_rng(0)
    try:
        expected = drive(rec, 60, lambda obs: rng.uniform(-1, 1, (3, 3)).astype(np.float32), seed=1, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 6 and len({len(ep["action"]) for ep in expected}) > 1
    assert rec.stats["episodes_written"] == len(expected)
    summary, arrays = load(root)
    task = envhub.EnvRegistry().get("mujoco-hopper").description
    check_against(summary, arrays, expected, task, video_key="observation.images.render")
    assert summary["features"]["observation.state"] == {"dtype": "float64", "shape": [11]}
    assert summary["features"]["observation.images.render"]["shape"] == [48, 64, 3]
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["fps"] == env.metadata["render_fps"] and info["codebase_version"] == "v3.0"
    assert "observation.state" in summary["stats_keys"] and "observation.images.render" in summary["stats_keys"]


def test_python_hosted_env_same_step(tmp_path):
    """A Python-hosted env (Gymnasium's CartPole, drawn by pygame; Discrete actions) under
    `same_step` autoreset."""
    env = envhub.make_vec("gym-cartpole", 2, num_workers=1, autoreset_mode="same_step", render_mode="rgb_array")
    root = tmp_path / "cartpole"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root))
    rng = np.random.default_rng(1)
    try:
        expected = drive(rec, 50, lambda obs: rng.integers(0, 2, 2), seed=3, same_step=True, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("gym-cartpole").description,
                  video_key="observation.images.render")
    assert summary["features"]["action"] == {"dtype": "int64", "shape": [1]}


def test_disabled_autoreset_with_masked_resets(tmp_path):
    """`autoreset_mode="disabled"`: an episode starts at the masked reset that the caller
    makes; an episode a full reset cuts short is not written."""
    env = envhub.make_vec("gym-pendulum", 2, num_workers=1, autoreset_mode="disabled", max_episode_steps=4)
    root = tmp_path / "disabled"
    rec = envhub.RecordEpisodes(env, str(root), video=False)
    rng = np.random.default_rng(6)
    expected, current = [], [{}, {}]
    try:
        obs, _ = rec.reset(seed=0)
        for t in range(11):
            if t == 2:  # env 1 starts over two steps late: its episodes end out of step with env 0's
                obs, _ = rec.reset(options={"reset_mask": np.array([False, True])})
                current[1] = {}
            actions = rng.uniform(-2, 2, (2, 1)).astype(np.float32)
            nobs, rewards, term, trunc, _ = rec.step(actions)
            for i in range(2):
                ep = current[i]
                ep.setdefault("observation.state", []).append(np.array(obs[i]))
                ep.setdefault("action", []).append(actions[i].copy())
                ep.setdefault("next.reward", []).append(float(rewards[i]))
                ep.setdefault("next.terminated", []).append(bool(term[i]))
                ep.setdefault("next.truncated", []).append(bool(trunc[i]))
            done = term | trunc
            obs = nobs
            for i in np.flatnonzero(done):
                expected.append(current[i])
                current[i] = {}
            if done.any():
                obs, _ = rec.reset(options={"reset_mask": done})
        rec.reset(seed=1)  # cuts the episodes in flight short: not written
    finally:
        rec.close()
    assert rec.stats["episodes_cut"] == 3 and len(expected) == 4  # env 1 at step 2, both at the end
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("gym-pendulum").description)


def test_envs_on_other_hubs(two_hubs, tmp_path):
    """Envs on two other hubs (`envhub serve` on loopback, reached over Zenoh), frames
    included: the recorder sees the same Gymnasium vector env."""
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 2, hubs=["pya", "pyb"], render_mode="rgb_array",
                          max_episode_steps=12, width=32, height=32)
    assert env.placement == [("pya", 0, 1), ("pyb", 1, 2)]
    root = tmp_path / "remote"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root))
    rng = np.random.default_rng(7)
    try:
        expected = drive(rec, 30, lambda obs: rng.uniform(-1, 1, (2, 3)).astype(np.float32), seed=2, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("mujoco-hopper").description,
                  video_key="observation.images.render")


def test_gymnasiums_own_vector_env(tmp_path):
    """Not only envhub's envs: Gymnasium's `SyncVectorEnv` records the same way (the task
    text is env 0's id)."""
    import gymnasium

    env = gymnasium.vector.SyncVectorEnv([lambda: gymnasium.make("CartPole-v1")] * 2)
    root = tmp_path / "sync"
    rec = envhub.RecordEpisodes(env, str(root))
    rng = np.random.default_rng(8)
    try:
        expected = drive(rec, 60, lambda obs: rng.integers(0, 2, 2), seed=4)
    finally:
        rec.close()
    summary, arrays = load(root)
    check_against(summary, arrays, expected, "CartPole-v1")


def _camera_env():
    import gymnasium

    env = gymnasium.make("InvertedPendulum-v5", render_mode="rgb_array", width=64, height=48, max_episode_steps=30)
    return gymnasium.wrappers.AddRenderObservation(env, render_only=False)


def test_dict_observation_with_a_camera(tmp_path):
    """A Dict observation with a camera image (Gymnasium's MuJoCo pendulum with its frames
    added to the observation), through the drop-in `envhub.AsyncVectorEnv`: the image
    becomes a video, the state a column."""
    env = envhub.AsyncVectorEnv([_camera_env, _camera_env])
    root = tmp_path / "camera"
    rec = envhub.RecordEpisodes(env, str(root), task="balance the pole")
    rng = np.random.default_rng(2)
    paths = {"observation.state": ("state",), "observation.images.pixels": ("pixels",)}
    try:
        expected = drive(rec, 40, lambda obs: rng.uniform(-3, 3, (2, 1)).astype(np.float32), seed=0, paths=paths)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, "balance the pole", cameras=("observation.images.pixels",))
    # The env renders too (`render_mode="rgb_array"`), so its `render()` frames are a video as well.
    assert summary["video_keys"] == ["observation.images.pixels", "observation.images.render"]


def test_a_suites_camera_observations(tmp_path):
    """A suite's own cameras: robosuite's Lift with agentview and wrist images (in its own
    Python environment, as `test_py_suites.py` builds it): two videos and sixteen columns.
    robosuite's envs declare no frame rate: its control rate, 20 Hz, is given."""
    try:
        env = envhub.make_vec("robosuite-lift-camera", 1, max_episode_steps=6)
    except envhub.EnvHubError as e:
        message = f"robosuite's environment cannot run here ({str(e).splitlines()[0]})"
        if os.environ.get("ENVHUB_SUITES_REQUIRED"):
            pytest.fail(f"{message}, and ENVHUB_SUITES_REQUIRED is set")
        pytest.skip(message)
    from envhub.recording._features import observation_columns

    paths = {c.name: c.path for c in observation_columns(env.single_observation_space)}
    cameras = tuple(name for name in paths if name.startswith("observation.images."))
    assert cameras == ("observation.images.agentview_image", "observation.images.robot0_eye_in_hand_image")
    root = tmp_path / "lift"
    rec = envhub.RecordEpisodes(env, str(root), fps=20)
    rng = np.random.default_rng(5)
    try:
        expected = drive(rec, 13, lambda obs: rng.uniform(-1, 1, (1, 7)).astype(np.float32), seed=0, paths=paths)
    finally:
        rec.close()
    assert len(expected) == 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("robosuite-lift-camera").description,
                  cameras=cameras)
    assert summary["fps"] == 20 and len(summary["features"]) == len(paths) + 5 + 5


# Filters, appending, layouts ---------------------------------------------------------------


def test_success_only_keeps_successful_episodes(tmp_path):
    """`keep="success"` on FetchReach (`is_success` info): env 0 reaches the goal (scripted),
    env 1 moves at random; only successful episodes are written, the others counted."""
    env = envhub.make_vec("fetch-reach", 2, num_workers=1)
    root = tmp_path / "fetch"
    rec = envhub.RecordEpisodes(env, str(root), keep="success", max_episodes=2)
    rng = np.random.default_rng(4)

    def act(obs):
        a = rng.uniform(-1, 1, (2, 4)).astype(np.float32)
        a[0, :3] = np.clip(10 * (obs["desired_goal"][0] - obs["achieved_goal"][0]), -1, 1)
        a[0, 3] = 0
        return a

    try:
        obs, _ = rec.reset(seed=0)
        for _ in range(300):
            obs, *_ = rec.step(act(obs))
            if rec.stats["episodes_kept"] >= 2 and rec.stats["episodes_filtered"] >= 1:
                break
    finally:
        rec.close()
    assert rec.stats["episodes_written"] == 2 and rec.stats["episodes_filtered"] >= 1
    summary, arrays = load(root)
    assert summary["num_episodes"] == 2 and summary["episode_success"] == [True, True]
    assert {"observation.observation", "observation.achieved_goal", "observation.desired_goal"} <= set(
        summary["features"]
    )


def test_success_only_needs_a_success_info(tmp_path):
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 1, max_episode_steps=3)
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), keep="success")
    try:
        rec.reset(seed=0)
        with pytest.raises(envhub.recording.RecordingError, match="`success` or `is_success`"):
            for _ in range(4):
                rec.step(rec.action_space.sample())
    finally:
        rec.close()


def test_append_and_a_dataset_of_another_layout(tmp_path):
    """Recording into an existing dataset appends episodes (indices go on); a dataset of
    another layout, or a folder that holds something else, is an error naming the mismatch."""
    root = tmp_path / "pendulum"
    first = envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=8, seed=0)
    second = envhub.record("gym-pendulum", 3, root, num_envs=2, video=False, max_episode_steps=8, seed=7)
    assert first["episodes_written"] == 2 and second["episodes_written"] == 3
    summary, arrays = load(root)
    assert summary["num_episodes"] == 5 and summary["episode_lengths"] == [8] * 5
    np.testing.assert_array_equal(arrays["raw/episode_index"], np.repeat(np.arange(5), 8))
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(40))

    with pytest.raises(envhub.recording.DatasetLayoutError) as err:
        envhub.record("gym-cartpole", 1, root, video=False)
    message = str(err.value)
    assert "feature `observation.state` is `float32` of shape [3] there, `float32` of shape [4] here" in message
    assert "feature `action`" in message and "hint:" in message
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(envhub.recording.DatasetLayoutError, match="holds no LeRobot dataset"):
        envhub.record("gym-pendulum", 1, other, video=False)
    assert (other / "notes.txt").read_text() == "mine"


def test_a_second_recorder_on_the_same_folder_is_refused(tmp_path):
    env_a = envhub.make_vec("gym-pendulum", 1)
    env_b = envhub.make_vec("gym-pendulum", 1)
    a = envhub.RecordEpisodes(env_a, str(tmp_path / "d"), video=False)
    b = envhub.RecordEpisodes(env_b, str(tmp_path / "d"), video=False)
    try:
        a.reset(seed=0)
        with pytest.raises(envhub.recording.RecordingError, match="being written by another recorder"):
            b.reset(seed=0)
    finally:
        a.close()
        b.close()


# The queue, crashes ------------------------------------------------------------------------


def _slow_writer_env():
    """Frames that take the writer far longer to encode (AV1 through libaom, 256x256) than
    the env takes to step and draw them."""
    mujoco_or_skip(envhub)
    return envhub.make_vec("mujoco-inverted-pendulum", 2, num_workers=1, render_mode="rgb_array",
                           max_episode_steps=20, width=256, height=256)


def test_full_queue_waits_and_says_so(tmp_path):
    env = _slow_writer_env()
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), queue_bytes=1, when_full="wait", codec="libaom-av1")
    try:
        with pytest.warns(envhub.recording.QueueFullWarning, match="steps wait for the writer"):
            expected = drive(rec, 45, lambda obs: np.zeros((2, 1), np.float32), seed=0)
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.close()
    assert rec.stats["steps_waited"] > 0 and rec.stats["seconds_waited"] > 0
    assert rec.stats["episodes_dropped"] == 0 and rec.stats["episodes_written"] == len(expected)
    summary, arrays = load(tmp_path / "d")
    check_against(summary, arrays, expected, summary["tasks"][0])


def test_full_queue_drops_whole_episodes_and_says_so(tmp_path):
    env = _slow_writer_env()
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), queue_bytes=1, when_full="drop", codec="libaom-av1")
    try:
        with pytest.warns(envhub.recording.QueueFullWarning, match="a step is dropped"):
            expected = drive(rec, 100, lambda obs: np.zeros((2, 1), np.float32), seed=0)
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.close()
    s = rec.stats
    assert s["steps_dropped"] > 0 and s["episodes_dropped"] > 0
    assert s["episodes_written"] + s["episodes_dropped"] <= len(expected) + rec.num_envs
    if s["episodes_written"]:
        # Whatever was written is whole: each episode is one the session ran, every frame of it
        # (the pendulum may fall before the 20-step limit, so lengths are the session's).
        summary, arrays = load(tmp_path / "d")
        assert len(summary["episode_lengths"]) == s["episodes_written"]
        for e in range(s["episodes_written"]):
            rows = arrays["raw/episode_index"] == e
            states = arrays["raw/observation.state"][rows]
            np.testing.assert_array_equal(arrays["raw/frame_index"][rows], np.arange(len(states)))
            same = [ep for ep in expected if np.array_equal(np.stack(ep["observation.state"]), states)]
            assert same, f"written episode {e} ({len(states)} frames) is none the session ran whole"


CRASHING_RECORDER = textwrap.dedent(
    """\
    import sys, numpy as np, envhub
    env = envhub.make_vec("mujoco-inverted-pendulum", 2, num_workers=1, render_mode="rgb_array",
                          max_episode_steps=10, width=32, height=32)
    rec = envhub.RecordEpisodes(env, sys.argv[1], commit_every=0.05)
    rec.reset(seed=0)
    while True:
        rec.step(np.zeros((2, 1), np.float32))
    """
)


def test_a_killed_recorder_leaves_a_dataset_that_loads(tmp_path):
    """`kill -9` in the middle of recording: the dataset loads with the episodes committed,
    and recording into it again appends after them."""
    mujoco_or_skip(envhub)
    root = tmp_path / "crash"
    script = tmp_path / "crash.py"
    script.write_text(CRASHING_RECORDER)
    proc = subprocess.Popen([sys.executable, str(script), str(root)], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            info = root / "meta" / "info.json"
            if info.exists() and json.loads(info.read_text())["total_episodes"] >= 6:
                break
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.02)
        else:
            pytest.fail("the recorder committed no 6 episodes in 120 s")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    summary, _ = load(root)
    committed = summary["num_episodes"]
    assert committed >= 6 and summary["episode_lengths"] == [10] * committed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # files a crash left are removed, and said so
        envhub.record("mujoco-inverted-pendulum", 2, root, num_envs=2, max_episode_steps=10, width=32, height=32)
    summary, arrays = load(root)
    assert summary["num_episodes"] == committed + 2 and summary["episode_lengths"][:committed] == [10] * committed
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(summary["num_frames"]))
    np.testing.assert_array_equal(np.unique(arrays["raw/episode_index"]), np.arange(committed + 2))


def test_files_a_crash_left_between_renames_are_removed(tmp_path):
    """A crash after a commit renamed its data and episode files into place but before
    `meta/info.json` leaves files the totals do not count: the next recording removes them,
    says so, and appends."""
    import shutil

    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    root = tmp_path / "d"
    envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=5)
    # What such a crash leaves: the data file and episodes file of a commit (episodes 2 and 3)
    # that `info.json` never counted.
    shutil.copy(root / "data/chunk-000/file-000.parquet", root / "data/chunk-000/file-001.parquet")
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet")
    column = episodes.schema.get_field_index("episode_index")
    episodes = episodes.set_column(column, "episode_index", pc.add(episodes.column(column), 2))
    pq.write_table(episodes, root / "meta/episodes/chunk-000/file-001.parquet")
    with pytest.warns(UserWarning, match=r"removed 2 file\(s\) of episodes that a crash left uncommitted"):
        envhub.record("gym-pendulum", 1, root, video=False, max_episode_steps=5)
    summary, arrays = load(root)
    assert summary["num_episodes"] == 3 and summary["num_frames"] == 15
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(15))


# The command line --------------------------------------------------------------------------


def _cli(*args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    from envhub._cli import BINARY

    if not BINARY.exists():
        _missing(f"the `envhub` binary is not built at `{BINARY}` (`make py-install`)")
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
