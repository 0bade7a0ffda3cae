"""One encoding per dataset: every append (the recorder, `envhub eval --record`'s writer) encodes
with the dataset's own stream parameters, read from `info.json` and its video files, or is
refused before anything in the folder changes; a dataset made by LeRobot's own writer (its
defaults: SVT-AV1) takes envhub's appends.

Judged by LeRobot's own loader (`lerobot_load.py`, in its interpreter): every frame it decodes
is compared with the image the env drew, which the frame's state (episode, step) names.
"""

from __future__ import annotations

import json
import subprocess
import textwrap
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from drawn_env import KEY, STEPS, Drawn, image
from harness import import_envhub
from lerobot_datasets import check_video, lerobot_python, load, snapshot

envhub = import_envhub()
from envhub.evaluation.dataset import EpisodeDataset  # noqa: E402
from envhub.recording import _encoding  # noqa: E402


def _vec(first: int) -> gymnasium.vector.SyncVectorEnv:
    return gymnasium.vector.SyncVectorEnv([lambda: Drawn(first), lambda: Drawn(first + 100)])


def _record(root: Path, first: int, **options) -> dict:
    """Two envs, two episodes each (episodes `first`, `first + 1` and `first + 100`, ...)."""
    rec = envhub.RecordEpisodes(_vec(first), str(root), task="draw", **options)
    try:
        rec.reset(seed=0)
        for _ in range(2 * (STEPS + 1)):
            rec.step(np.zeros((2, 1), np.float32))
    finally:
        rec.close()
    return rec.stats


def _evaluate(root: Path, first: int, **options) -> None:
    """Two episodes through `envhub eval --record`'s writer, as its runner drives it."""
    envs = _vec(first)
    ds = EpisodeDataset(root, **options)
    ds.session(envs, "draw")
    for slot in range(2):
        env = Drawn(first + slot)
        obs, _ = env.reset()
        for _ in range(STEPS):
            ds.observe(slot, obs)
            action = np.zeros(1, np.float32)
            obs, reward, terminated, truncated, _ = env.step(action)
            ds.step(slot, action, reward, terminated)
        ds.finish(slot, "draw", None)
    ds.close()
    envs.close()


def _check_frames(root: Path, episodes: int) -> dict:
    """LeRobot's loader reads `episodes` episodes whose every frame is the image its state names."""
    summary, arrays = load(root)
    assert summary["num_episodes"] == episodes and summary["num_frames"] == episodes * STEPS
    states = arrays["raw/observation.state"].astype(int)
    drawn = np.stack([image(ep, t) for ep, t in states])
    check_video(arrays[KEY], drawn)
    return summary


def _mp4s(root: Path) -> list[Path]:
    return sorted((root / "videos" / KEY).glob("*/*.mp4"))


def _x264_settings(path: Path) -> list[tuple[str, str]]:
    """The CRF and keyint x264 wrote into each episode's first packet, over the whole file."""
    import av

    with av.open(str(path)) as src:
        found = [_encoding._x264_options(bytes(p)) for p in src.demux(video=0) if p.size]
    return [(o["crf"], o["keyint"]) for o in found if o is not None]


def _untag(path: Path) -> None:
    """`path` remuxed without envhub's tag (what envhub wrote before it tagged its videos)."""
    import av

    tmp = path.with_suffix(".tmp.mp4")
    with av.open(str(path)) as src, av.open(str(tmp), "w", format="mp4") as dst:
        stream = dst.add_stream_from_template(src.streams.video[0], opaque=True)
        for packet in src.demux(video=0):
            if packet.size:
                packet.stream = stream
                dst.mux(packet)
    tmp.replace(path)
    with av.open(str(path)) as src:
        assert "comment" not in src.metadata


def test_appends_encode_with_the_datasets_parameters(tmp_path):
    """A dataset recorded at `crf=28`, `gop=4` takes appends from the recorder and from
    `eval --record` left to their defaults in that encoding (read from its files: envhub's tag,
    or x264's own options where the tag is missing), and LeRobot's loader decodes every frame
    of every append as drawn."""
    root = tmp_path / "x264"
    _record(root, 0, crf=28, gop=4)
    _untag(_mp4s(root)[-1])
    assert _encoding.read(_mp4s(root)[-1], json.loads((root / "meta/info.json").read_text())["features"][KEY]) == (
        _encoding.Encoding("libx264", 28, 4, "yuv420p", 64, 48))
    _record(root, 10)
    _evaluate(root, 20)
    [mp4] = _mp4s(root)
    import av

    with av.open(str(mp4)) as src:
        assert src.metadata["comment"] == "envhub-encoding encoder=libx264 crf=28 g=4"
    assert _x264_settings(mp4) == [("28.0", "4")] * 10  # each episode's encoder's own say
    _check_frames(root, 10)


@pytest.mark.parametrize("asked", [{"crf": 40}, {"codec": "libopenh264"}, {"gop": 3}, {"codec": "libsvtav1"}],
                         ids=["crf", "openh264", "gop", "av1"])
def test_other_parameters_are_refused_before_anything_is_touched(tmp_path, asked):
    """Asking an x264 `crf=18` dataset for another CRF, encoder (openh264 is H.264 too) or GOP
    is a `DatasetLayoutError` naming it, from the recorder and from `eval --record`, and the
    folder (here one a crash left, with `.envhub/`) is left byte for byte as it was."""
    root = tmp_path / "x264"
    _record(root, 0)
    (root / ".envhub" / "staging").mkdir(parents=True)
    (root / ".envhub" / "staging" / "left.mp4").write_bytes(b"a crash's leftover")
    before = snapshot(root)
    with pytest.raises(envhub.recording.DatasetLayoutError, match="in its own encoding") as err:
        _record(root, 10, **asked)
    name = next(iter(asked))
    assert (f"{name}={asked[name]}" if name != "codec" else f"`{asked[name]}` asked") in str(err.value)
    assert snapshot(root) == before
    with pytest.raises(envhub.recording.DatasetLayoutError, match="in its own encoding"):
        _evaluate(root, 20, **asked)
    assert snapshot(root) == before
    _check_frames(root, 4)


def test_a_stream_that_cannot_be_reproduced_is_refused(tmp_path, monkeypatch):
    """Where the parameters read would not give the file's stream configuration (here: envhub's
    x264 options changed since the dataset was written), the append is refused untouched."""
    root = tmp_path / "x264"
    _record(root, 0)
    before = snapshot(root)
    monkeypatch.setitem(_encoding.CODECS, "libx264", {"preset": "veryslow"})
    with pytest.raises(envhub.recording.DatasetLayoutError, match="another stream configuration"):
        _record(root, 10)
    assert snapshot(root) == before


LEROBOT_AV1_WRITER = textwrap.dedent(
    """\
    # In LeRobot's interpreter: LeRobot's own writer, its video defaults (SVT-AV1), four episodes
    # of the test's drawn frames.
    import sys
    import numpy as np
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
    except ImportError:
        from ledataset.datasets.lerobot_dataset import LeRobotDataset

    def image(ep, t):
        y, x = np.mgrid[0:48, 0:64]
        return np.stack([x * 2 + t * 5, y * 3 + ep * 23 % 100, (x + y) * 2 + t], -1).astype(np.uint8)

    one = {"dtype": "bool", "shape": (1,), "names": None}
    features = {
        "observation.state": {"dtype": "float32", "shape": (2,), "names": None},
        "observation.images.pixels": {"dtype": "video", "shape": (48, 64, 3), "names": ["height", "width", "channels"]},
        "action": {"dtype": "float32", "shape": (1,), "names": None},
        "next.reward": {"dtype": "float64", "shape": (1,), "names": None},
        "next.done": one, "next.terminated": one, "next.truncated": one,
    }
    ds = LeRobotDataset.create("envhub/lerobot-av1", fps=10, features=features, root=sys.argv[1])
    for ep in (0, 1, 100, 101):
        for t in range(STEPS):
            last = t == STEPS - 1
            ds.add_frame({"observation.state": np.array([ep, t], np.float32), "observation.images.pixels": image(ep, t),
                          "action": np.zeros(1, np.float32), "next.reward": np.ones(1), "next.done": np.array([last]),
                          "next.terminated": np.array([False]), "next.truncated": np.array([last]), "task": "draw"})
        ds.save_episode()
    ds.finalize()
    """
).replace("STEPS", str(STEPS))


def test_a_dataset_lerobots_writer_made_takes_appends(tmp_path):
    """A dataset from LeRobot's own writer with its defaults (SVT-AV1, CRF 30, a keyframe every
    2 frames; no envhub tag) takes appends from the recorder and from `eval --record`, both
    left to their defaults (x264), in AV1: `info.json` still says `av1`, and LeRobot's loader
    decodes every frame of all fourteen episodes as drawn."""
    root = tmp_path / "theirs"
    script = tmp_path / "writer.py"
    script.write_text(LEROBOT_AV1_WRITER)
    proc = subprocess.run([lerobot_python(), str(script), str(root)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    info = json.loads((root / "meta/info.json").read_text())
    assert info["features"][KEY]["info"]["video.codec"] == "av1"
    with warnings.catch_warnings():  # its `stats.json` is its episodes' (LeRobot's aggregate)
        warnings.filterwarnings("error", message=".*did not describe the committed episodes")
        _record(root, 10)
    _evaluate(root, 20)
    _record(root, 30)
    info = json.loads((root / "meta/info.json").read_text())
    assert info["features"][KEY]["info"]["video.codec"] == "av1" and info["total_episodes"] == 14
    import av

    for mp4 in _mp4s(root):
        with av.open(str(mp4)) as src:
            assert src.streams.video[0].codec_context.codec.name in ("libdav1d", "av1", "libaom-av1")
    _check_frames(root, 14)
