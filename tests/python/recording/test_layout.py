"""LeRobot v3's layout: many episodes per file, files rolling at the declared sizes, and no
more files than LeRobot's own writer makes for the same episodes. Judged by LeRobot's own
loader (`support/lerobot_datasets.py`)."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip
from lerobot_datasets import (
    check_against,
    dataset_files,
    lerobot_python,
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
    )
from recorded_episodes import Episodes

envhub = import_envhub()


# LeRobot v3's layout: many episodes per file --------------------------------------------------


def _drive_pendulums(rec, steps: int, seed: int) -> list[dict[str, list]]:
    """Steps native MuJoCo pendulums (`next_step` autoreset) with random actions; returns the
    episodes that ended as the session returned them, `render()` frames included."""
    rng = np.random.default_rng(seed)
    n = rec.num_envs
    seen = Episodes(n)
    obs, _ = rec.reset(seed=seed)
    shown = rec.render()
    fresh = np.zeros(n, dtype=bool)
    for _ in range(steps):
        actions = rng.uniform(-3, 3, (n, 1)).astype(np.float32)
        nobs, rewards, term, trunc, _ = rec.step(actions)
        for i in np.flatnonzero(~fresh):
            seen.add(i, obs[i], actions[i], rewards[i], term[i], trunc[i], frame=shown[i])
        obs, fresh, shown = nobs, term | trunc, rec.render()
    return seen.ended


def _record_many(root, steps: int, seed: int, **sizes) -> list[dict[str, list]]:
    env = envhub.make_vec("mujoco-inverted-pendulum", 8, num_workers=1, render_mode="rgb_array",
                          max_episode_steps=4, width=16, height=16)
    rec = envhub.RecordEpisodes(env, str(root), task="balance", commit_every=0.05, **sizes)
    try:
        expected = _drive_pendulums(rec, steps, seed)
    finally:
        rec.close()
    assert rec.stats["episodes_written"] == len(expected)
    return expected


def _check_addresses(root, fps: int) -> dict[str, list]:
    """Episodes are addressed by contiguous index ranges, and by time ranges that follow one
    another in each video file from 0."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    eps = pa.concat_tables(
        [pq.read_table(p) for p in sorted((root / "meta/episodes").glob("*/*.parquet"))]).to_pydict()
    lengths = np.array(eps["length"])
    ends = np.cumsum(lengths)
    np.testing.assert_array_equal(eps["dataset_to_index"], ends)
    np.testing.assert_array_equal(eps["dataset_from_index"], ends - lengths)
    key = "videos/observation.images.render"
    at = list(zip(eps[f"{key}/chunk_index"], eps[f"{key}/file_index"], strict=True))
    start = 0.0
    for e in range(len(lengths)):
        if e and at[e] != at[e - 1]:
            start = 0.0
        assert eps[f"{key}/from_timestamp"][e] == pytest.approx(start)
        assert eps[f"{key}/to_timestamp"][e] == pytest.approx(start + lengths[e] / fps)
        start = eps[f"{key}/to_timestamp"][e]
    return eps


def test_many_short_episodes_share_a_handful_of_files(tmp_path):
    """Hundreds of short episodes with a small camera: one data file, one episodes file, one
    MP4 (as LeRobot's writer makes them), episodes addressed by index and time ranges;
    LeRobot's loader reads states and actions bit for bit and every frame. Appending goes on
    in the same files."""
    mujoco_or_skip(envhub)
    root = tmp_path / "many"
    expected = _record_many(root, 120, seed=0)
    expected += _record_many(root, 30, seed=1)
    assert len(expected) >= 200
    assert dataset_files(root) == [
        "data/chunk-000/file-000.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
        "videos/observation.images.render/chunk-000/file-000.mp4",
    ], dataset_files(root)
    summary, arrays = load(root)
    _check_addresses(root, summary["fps"])
    check_against(summary, arrays, expected, "balance", video_key="observation.images.render")


def test_files_roll_at_the_declared_sizes(tmp_path):
    """With small `data_files_size_in_mb` / `video_files_size_in_mb` the files roll: each
    stays near the size (one commit past it at most), the dataset loads whole, and an append
    continues the last file where it has room."""
    mujoco_or_skip(envhub)
    root = tmp_path / "rolled"
    sizes = {"data_files_size_in_mb": 0.02, "video_files_size_in_mb": 0.05}
    expected = _record_many(root, 100, seed=0, **sizes)
    data = sorted((root / "data").glob("*/*.parquet"))
    videos = sorted((root / "videos").glob("*/*/*.mp4"))
    assert len(data) >= 2 and len(videos) >= 2, (data, videos)
    last_video = videos[-1].stat().st_size
    before_bytes = sum(v.stat().st_size for v in videos)
    expected += _record_many(root, 4, seed=1, **sizes)
    # The append goes on in the last file, unless adding to it would reach the size
    # (LeRobot's rule): how full the first recording left it depends on how its episodes
    # fell into commits, so either can happen, but a roll only where the size was reached.
    # Where the last two files together were under the size, the append's joins may take both
    # and its own file into the earlier name: one file fewer. The files before stay.
    after = sorted((root / "videos").glob("*/*/*.mp4"))
    kept = max(len(videos) - 2, 0)
    assert after[:kept] == videos[:kept] and len(videos) - 1 <= len(after) <= len(videos) + 1, (videos, after)
    info = json.loads((root / "meta/info.json").read_text())
    assert info["data_files_size_in_mb"] == 0.02 and info["video_files_size_in_mb"] == 0.05
    summary, arrays = load(root)
    eps = _check_addresses(root, summary["fps"])
    if len(after) <= len(videos):
        # Continued in place: the last file grew, or (where the last two files together were
        # still under the size) the two were joined into the earlier name and the appended
        # episodes took the last name or joined them too; either way the files hold more and
        # load whole (below).
        grew = videos[-1].exists() and videos[-1].stat().st_size > last_video
        rejoined = videos[-2].stat().st_size > before_bytes - last_video - sum(
            v.stat().st_size for v in videos[:-2]
        )
        assert grew or rejoined, (last_video, [v.stat().st_size for v in after])
        assert sum(v.stat().st_size for v in after) > before_bytes
    else:
        # LeRobot's rule adds each episode's own MP4 to the last file's size, its container's
        # boxes included (about 830 bytes for these); joined into a file, an episode adds its
        # packets: the new file's episodes (the last file's) are allowed 1 KiB each.
        key = "videos/observation.images.render"
        address = list(zip(eps[f"{key}/chunk_index"], eps[f"{key}/file_index"], strict=True))
        joined = address.count(address[-1])
        both = videos[-1].stat().st_size + after[-1].stat().st_size + joined * 1024
        assert both / 2**20 >= sizes["video_files_size_in_mb"], (last_video, both, joined)
    check_against(summary, arrays, expected, "balance", video_key="observation.images.render")


LEROBOT_WRITER = textwrap.dedent(
    """\
    # In LeRobot's interpreter: LeRobot's own writer given the same episodes (states, actions,
    # decoded frames) as the dataset at argv[1]; prints the files each holds.
    import inspect, json, sys
    from pathlib import Path
    import av, numpy as np, pyarrow as pa, pyarrow.parquet as pq
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
    except ImportError:
        from ledataset.datasets.lerobot_dataset import LeRobotDataset

    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    info = json.loads((src / "meta/info.json").read_text())
    data = pa.concat_tables([pq.read_table(p) for p in sorted((src / "data").glob("*/*.parquet"))])
    eps = pa.concat_tables([pq.read_table(p) for p in sorted((src / "meta/episodes").glob("*/*.parquet"))])
    key = "observation.images.render"
    frames = {}
    for mp4 in sorted((src / "videos" / key).glob("*/*.mp4")):
        with av.open(str(mp4)) as c:
            frames[mp4.relative_to(src)] = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    feats = {k: {"dtype": f["dtype"], "shape": tuple(f["shape"]), "names": f.get("names")}
             for k, f in info["features"].items() if k in ("observation.state", "action", key)}
    if "vcodec" in inspect.signature(LeRobotDataset.create).parameters:  # lerobot-dataset 0.4
        codec = {"vcodec": "h264"}
    else:  # lerobot 0.6: the codec in an encoder config
        from lerobot.configs.video import RGBEncoderConfig
        codec = {"rgb_encoder": RGBEncoderConfig(vcodec="h264")}
    ds = LeRobotDataset.create("envhub/theirs", fps=info["fps"], features=feats, root=out, **codec)
    state = np.array(data.column("observation.state").to_pylist())
    action = np.array(data.column("action").to_pylist(), dtype=np.float32).reshape(data.num_rows, -1)
    for e in range(eps.num_rows):
        row = {c: eps.column(c)[e].as_py() for c in eps.column_names if not c.startswith("stats/")}
        rel = Path(info["video_path"].format(video_key=key, chunk_index=row[f"videos/{key}/chunk_index"],
                                             file_index=row[f"videos/{key}/file_index"]))
        first = round(row[f"videos/{key}/from_timestamp"] * info["fps"])
        for k in range(row["length"]):
            i = row["dataset_from_index"] + k
            ds.add_frame({"observation.state": state[i], "action": action[i], key: frames[rel][first + k],
                          "task": row["tasks"][0]})
        ds.save_episode()
    ds.finalize()
    print(json.dumps(sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())))
    """
)


def test_as_few_files_as_lerobots_own_writer(tmp_path):
    """LeRobot's own writer, given the same episodes (states, actions, frames), writes as many
    files as this recorder (the issue asks within a factor of 2; they are the same files)."""
    import subprocess

    python = lerobot_python()
    mujoco_or_skip(envhub)
    root = tmp_path / "ours"
    expected = _record_many(root, 40, seed=3)
    assert len(expected) >= 60
    script = tmp_path / "writer.py"
    script.write_text(LEROBOT_WRITER)
    proc = subprocess.run([python, str(script), str(root), str(tmp_path / "theirs")], capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-4000:]
    theirs = json.loads(proc.stdout.strip().splitlines()[-1])
    ours = dataset_files(root)
    assert len(ours) <= 2 * len(theirs) and len(theirs) <= 2 * len(ours), (ours, theirs)
    assert ours == theirs  # lerobot-dataset 0.4.4: the very same six files
