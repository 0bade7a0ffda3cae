"""Recording rollouts into LeRobot v3 datasets, judged by LeRobot's own loader.

Real envs (native MuJoCo, the Gymnasium-hosted adapter, a plain Gymnasium vector env with a
camera in a Dict observation), the real encoder (PyAV's libx264) and the real loader
(`lerobot-dataset`). Without `pyarrow`, `av`, `torch` or `ledataset` the tests skip, unless
`ENVHUB_RECORD_REQUIRED` is set (as `make test` does), when they fail.
"""

from __future__ import annotations

import importlib
import os
import warnings

import numpy as np
import pytest
from conftest import import_envhub, mujoco_or_skip

# Decoded H.264 (crf 18, yuv420p) frames against the rendered RGB frames: mean absolute error
# per channel value, out of 255.
VIDEO_MAE = 4.0


def _need(*modules: str) -> None:
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            message = f"`{name}` is not installed ({exc}); recording tests need pyarrow, av, torch, ledataset"
            if os.environ.get("ENVHUB_RECORD_REQUIRED"):
                pytest.fail(f"{message}, and ENVHUB_RECORD_REQUIRED is set")
            pytest.skip(message)


@pytest.fixture
def envhub():
    mod = import_envhub()
    _need("pyarrow", "av", "torch", "torchvision", "ledataset")
    return mod


def task_of(id: str) -> str:
    from envhub.record import task_of as f

    return f(id)


def _layout_error():
    from envhub.record import LayoutError

    return LayoutError


def _load(repo_id: str, root):
    from ledataset.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


def _rollout(rec, steps: int, seed: int = 0):
    """Steps `rec` with seeded random actions; returns per env the frames of its ended
    episodes as (obs, render, action) lists, as the session returned them."""
    obs, _ = rec.reset(seed=seed)
    rec.action_space.seed(seed)
    n = rec.num_envs
    frames = [rec.render()[i].copy() for i in range(n)] if rec._render else [None] * n
    cur = [[] for _ in range(n)]
    ended = []
    fresh = np.zeros(n, dtype=bool)
    for _ in range(steps):
        act = rec.action_space.sample()
        prev = (np.array(obs, copy=True), frames)
        obs, _, term, trunc, _ = rec.step(act)
        frames = [rec.render()[i].copy() for i in range(n)] if rec._render else [None] * n
        for i in range(n):
            if fresh[i]:
                continue
            cur[i].append((prev[0][i], prev[1][i], np.array(act[i], copy=True)))
            if term[i] or trunc[i]:
                ended.append(cur[i])
                cur[i] = []
        fresh = np.logical_or(term, trunc)
    rec.close()
    return ended


def _check_against(ds, episodes, render: bool) -> None:
    """Episode `k` of the dataset is `episodes[k]`: states and actions bit for bit, frames
    within `VIDEO_MAE`."""
    assert ds.num_episodes == len(episodes)
    assert ds.num_frames == sum(len(e) for e in episodes)
    # The loader's rows as stored (the env's dtypes), and its items (torch's float32).
    table = ds.hf_dataset.with_format("arrow")[:]

    def column(name):
        col = table[name].combine_chunks()
        flat = col.flatten() if hasattr(col, "flatten") else col
        return flat.to_numpy(zero_copy_only=False).reshape(len(table), -1)

    raw = {"observation.state": column("observation.state"), "action": column("action")}
    idx = 0
    for k, ep in enumerate(episodes):
        for t, (obs, frame, act) in enumerate(ep):
            row = {key: raw[key][idx] for key in raw}
            item = ds[idx]
            assert int(item["episode_index"]) == k and int(item["frame_index"]) == t
            want = np.asarray(obs).reshape(-1)
            got = np.asarray(row["observation.state"]).reshape(-1)
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
            np.testing.assert_array_equal(
                item["observation.state"].numpy(), want.astype(item["observation.state"].numpy().dtype)
            )
            got_act = np.asarray(row["action"]).reshape(-1)
            want_act = np.asarray(act).reshape(-1)
            assert got_act.dtype == want_act.dtype
            np.testing.assert_array_equal(got_act, want_act)
            if render and t % 4 == 0:
                got = (item["observation.images.render"].permute(1, 2, 0).numpy() * 255.0)
                mae = np.abs(got - frame.astype(np.float64)).mean()
                assert mae < VIDEO_MAE, f"episode {k} frame {t}: mean abs error {mae:.2f}"
            idx += 1


def test_native_mujoco_episodes_load_in_lerobot(envhub, tmp_path):
    mujoco_or_skip(envhub)
    root = tmp_path / "ant"
    env = envhub.make_vec("mujoco-ant", 2, render_mode="rgb_array", max_episode_steps=6)
    rec = envhub.RecordEpisodes(env, str(root), repo_id="test/ant", task=task_of("mujoco-ant"))
    episodes = _rollout(rec, 14)
    assert len(episodes) == 4 and rec.stats["episodes_written"] == 4
    ds = _load("test/ant", root)
    assert ds.fps == 20
    _check_against(ds, episodes, render=True)
    assert ds[0]["task"] == task_of("mujoco-ant") != "mujoco-ant"
    assert (root / "videos/observation.images.render/chunk-000/file-000.mp4").exists()

    # Appending: a second run adds episodes after the first ones.
    env = envhub.make_vec("mujoco-ant", 2, render_mode="rgb_array", max_episode_steps=6)
    rec = envhub.RecordEpisodes(env, str(root), repo_id="test/ant", task=task_of("mujoco-ant"))
    more = _rollout(rec, 7, seed=1)
    ds = _load("test/ant", root)
    _check_against(ds, episodes + more, render=True)


def test_hosted_cartpole_and_record_function(envhub, tmp_path):
    root = tmp_path / "cartpole"
    stats = envhub.record("gym-cartpole", 3, root, num_envs=2, max_episode_steps=5)
    assert stats["episodes_written"] >= 3
    ds = _load("envhub/gym-cartpole", root)
    assert ds.num_episodes == stats["episodes_written"]
    assert ds.num_frames == 5 * ds.num_episodes
    assert "observation.images.render" in ds.meta.video_keys
    assert ds[ds.num_frames - 1]["next.done"].item() is True


def test_hosted_cartpole_exact(envhub, tmp_path):
    root = tmp_path / "cp"
    env = envhub.make_vec("gym-cartpole", 2, render_mode="rgb_array", max_episode_steps=4)
    rec = envhub.RecordEpisodes(env, str(root), repo_id="test/cp")
    episodes = _rollout(rec, 9)
    _check_against(_load("test/cp", root), episodes, render=True)


def test_another_layout_is_an_error_naming_it(envhub, tmp_path):
    root = tmp_path / "cp"
    envhub.record("gym-cartpole", 1, root, num_envs=1, max_episode_steps=3, video=False)
    with pytest.raises(_layout_error(), match="observation.images.render"):
        envhub.record("gym-cartpole", 1, root, num_envs=1, max_episode_steps=3, video=True)
    mujoco_or_skip(envhub)
    with pytest.raises(_layout_error(), match="observation.state.*action|fps"):
        envhub.record("mujoco-half-cheetah", 1, root, num_envs=1, max_episode_steps=3, video=False)
    assert _load("envhub/gym-cartpole", root).num_episodes == 1


def test_success_filter_with_a_dict_camera_observation(envhub, tmp_path):
    """A plain Gymnasium vector env: CartPole with its camera as a Dict entry, and a success
    flag in its info on even episodes only."""
    import gymnasium as gym

    class Flag(gym.Wrapper):
        def __init__(self, env):
            super().__init__(env)
            self.count = 0

        def reset(self, **kw):
            self.count += 1
            return self.env.reset(**kw)

        def step(self, a):
            obs, r, term, trunc, info = self.env.step(a)
            info["is_success"] = self.count % 2 == 0
            return obs, r, term, trunc, info

    def make():
        env = gym.make("CartPole-v1", render_mode="rgb_array", max_episode_steps=4)
        return Flag(gym.wrappers.AddRenderObservation(env, render_only=False))

    vec = gym.vector.SyncVectorEnv([make, make])
    root = tmp_path / "dict"
    rec = envhub.RecordEpisodes(vec, str(root), repo_id="test/dict", fps=30, filter="success", video=False)
    obs, _ = rec.reset(seed=0)
    for _ in range(20):
        obs, *_ = rec.step(rec.action_space.sample())
    rec.close()
    s = rec.stats
    assert s["episodes_written"] > 0 and s["episodes_filtered"] > 0
    ds = _load("test/dict", root)
    assert ds.num_episodes == s["episodes_written"]
    assert ds.meta.video_keys == ["observation.images.pixels"]
    assert ds[0]["observation.images.pixels"].shape == (3, 400, 600)
    assert ds[0]["observation.state"].shape == (4,)


def test_a_full_queue_with_drop_reports_the_drops(envhub, tmp_path):
    env = envhub.make_vec("gym-cartpole", 4, render_mode="rgb_array", max_episode_steps=20)
    rec = envhub.RecordEpisodes(env, str(tmp_path / "q"), repo_id="test/q", queue_size=1, when_full="drop")
    rec.reset(seed=0)
    for _ in range(60):
        rec.step(rec.action_space.sample())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec.close()
    assert rec.stats["steps_dropped"] > 0 and rec.stats["episodes_dropped"] > 0
    assert any("dropped" in str(w.message) for w in caught)
    ds = _load("test/q", tmp_path / "q")
    # Only whole episodes: each starts at frame 0, counts up, and ends done.
    frames = ds.hf_dataset.with_format("arrow")[:]
    ends = np.asarray(frames["next.done"])
    index = np.asarray(frames["frame_index"])
    episode = np.asarray(frames["episode_index"])
    for k in range(ds.num_episodes):
        mine = episode == k
        assert (index[mine] == np.arange(mine.sum())).all() and ends[mine][-1]
        assert not ends[mine][:-1].any()


def test_cli_video(envhub, tmp_path):
    import av
    from envhub.record.__main__ import main

    out = tmp_path / "cp.mp4"
    assert main(["gym-cartpole", "--video", str(out), "--steps", "12"]) == 0
    with av.open(str(out)) as f:
        assert sum(1 for _ in f.decode(video=0)) == 13


def test_files_of_an_episode_in_flight_are_removed_on_reopening(envhub, tmp_path):
    """A crash after an episode's data file but before `info.json`: the dataset still loads,
    and recording into it again removes the stray files and appends after the counted ones."""
    import shutil

    from envhub.record import record

    root = tmp_path / "crash"
    record("gym-cartpole", 1, root, num_envs=1, max_episode_steps=3, video=False)
    data = root / "data/chunk-000"
    shutil.copy(data / "file-000.parquet", data / "file-001.parquet")
    (data / ".file-002.parquet.tmp").write_bytes(b"partial")
    assert _load("envhub/gym-cartpole", root).num_episodes == 1
    record("gym-cartpole", 1, root, num_envs=1, max_episode_steps=3, video=False)
    assert not (data / ".file-002.parquet.tmp").exists()
    ds = _load("envhub/gym-cartpole", root)
    assert ds.num_episodes == 2 and ds.num_frames == 6
    assert [int(ds[i]["episode_index"]) for i in (0, 3)] == [0, 1]


def test_the_envhub_cli_records_a_dataset_and_a_video(envhub, tmp_path):
    """`envhub record` and `envhub run --video`, the Rust CLI, through the Python recorder."""
    import subprocess

    import av
    from envhub._cli import BINARY

    mujoco_or_skip(envhub)
    out = tmp_path / "ds"
    done = subprocess.run(
        [str(BINARY), "record", "mujoco-half-cheetah", "--episodes", "2", "--out", str(out),
         "--num-envs", "2", "--max-episode-steps", "5", "--no-video"],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    ds = _load("envhub/mujoco-half-cheetah", out)
    assert ds.meta.total_episodes >= 2 and ds.meta.total_frames >= 10
    video = tmp_path / "look.mp4"
    done = subprocess.run(
        [str(BINARY), "run", "gym-cartpole", "--video", str(video), "--video-steps", "8"],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    with av.open(str(video)) as f:
        assert sum(1 for _ in f.decode(video=0)) == 9
    bad = subprocess.run([str(BINARY), "record", "no-such-env", "--out", str(tmp_path / "x")],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0 and "no-such-env" in bad.stderr
