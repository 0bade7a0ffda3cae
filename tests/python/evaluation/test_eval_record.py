"""`envhub eval --record DIR`: every evaluated episode into a LeRobot dataset, judged by
LeRobot's own loader (`lerobot_load.py` in `.venv-lerobot/`, as recording/test_record.py does).

- Pendulum (state observations, 2 envs, settling steps): the dataset holds each episode's
  frames from the first observation after settling; replaying the recorded actions in
  Gymnasium's own Pendulum from the episode's seed and settling gives the recorded
  observations and rewards bit for bit; returns equal the results file's, tasks and
  `next.done` are right, the settling steps are not frames.
- robosuite Lift with cameras (in its own Python environment): both cameras become videos
  whose decoded frames are the observations within the codec's tolerance.
- Tasks whose spaces differ cannot share a dataset: the error names both tasks.

Without pyarrow/PyAV or LeRobot's loader these skip with the reason, unless
ENVHUB_RECORD_REQUIRED is set (as `make py-test` does); robosuite's test skips without its
environment unless ENVHUB_SUITES_REQUIRED is set. A suite declares its frame rate (robosuite's
and LIBERO's control frequency, as `render_fps`), which the dataset's timestamps take.
"""

from __future__ import annotations

import json
import os

import gymnasium as gym
import numpy as np
import pytest
from eval_policies import (
    policies,  # noqa: F401 (a fixture: the test policies' file)
    run_cli,
)
from harness import import_envhub
from lerobot_datasets import (
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
)
from suite_envs import suite_python

envhub = import_envhub()
# As the suites' tests set it: robosuite renders offscreen through EGL (a GPU's or Mesa's).
os.environ.setdefault("MUJOCO_GL", "egl")

from envhub.evaluation import evaluate  # noqa: E402
from envhub.recording import RecordingError  # noqa: E402

CAMERAS = ["agentview_image", "robot0_eye_in_hand_image"]
MEAN_ABS_TOLERANCE = 5.0  # levels of 255, as recording/test_record.py allows x264 at CRF 18

PENDULUM = {
    "name": "pendulum-rec",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 3,
    "init": {"seed_start": 20},
    "horizon": 25,
    "settle": {"steps": 4, "action": [0.5]},
    "success": "none",
}


def swing(observations, tasks):
    return np.stack([np.array([np.tanh(3 * o[1] - o[2])], dtype=np.float32) for o in observations])


def test_pendulum_episodes_replay_bit_for_bit_in_gymnasium(tmp_path):
    results = evaluate(PENDULUM, swing, num_envs=2, out=tmp_path / "out", record=tmp_path / "ds", progress=False)
    summary, data = load(tmp_path / "ds")
    assert summary["num_episodes"] == 3 and summary["episode_lengths"] == [25, 25, 25], summary
    assert results["run"]["dataset"]["episodes_written"] == 3
    episodes = data["raw/episode_index"]
    state, action = data["raw/observation.state"], data["raw/action"].reshape(-1, 1)
    reward, done = data["raw/next.reward"], data["raw/next.done"]
    by_index = {e["index"]: e for e in results["episodes"]}
    seen = set()
    for ep in np.unique(episodes):
        rows = np.flatnonzero(episodes == ep)
        # Which evaluation episode: the one whose seed's settled state is the first frame.
        env = gym.make("Pendulum-v1")
        match = None
        for k, result in by_index.items():
            obs, _ = env.reset(seed=result["init"]["seed"])
            for _ in range(PENDULUM["settle"]["steps"]):
                obs, *_ = env.step(np.array([0.5], np.float32))
            if np.array_equal(obs, state[rows[0]]):
                match = k
                break
        assert match is not None and match not in seen, f"episode {ep}: no evaluation episode starts at {state[rows[0]]}"
        seen.add(match)
        for t, row in enumerate(rows):
            assert np.array_equal(obs, state[row]), (ep, t)
            assert np.array_equal(action[row], swing([state[row]], None)[0]), (ep, t)
            obs, r, *_ = env.step(action[row])
            assert r == reward[row], (ep, t)
        assert list(done[rows]) == [False] * 24 + [True]
        assert float(reward[rows].sum()) == pytest.approx(by_index[match]["return"], rel=1e-12)
    assert seen == {0, 1, 2}
    assert all(t == results["tasks"][0]["text"] for t in summary["tasks"]), summary["tasks"][:3]


def test_tasks_of_other_spaces_cannot_share_a_dataset(tmp_path):
    bench = {**PENDULUM, "entries": ["gym-pendulum", "gym-mountain-car-continuous"], "episodes_per_task": 1}
    bench["settle"] = {"steps": 0}

    def act(observations, tasks):
        return np.zeros((len(observations), 1), np.float32)

    with pytest.raises(RecordingError) as e:
        evaluate(bench, act, out=tmp_path / "out", record=tmp_path / "ds", progress=False)
    message = str(e.value)
    assert "gym-mountain-car-continuous" in message and "gym-pendulum" in message, message
    assert "observation.state float32[3]" in message and "float32[2]" in message, message


def test_robosuite_cameras_become_videos(tmp_path):
    bench = {
        "name": "lift-rec",
        "entries": ["robosuite-lift-camera"],
        "episodes_per_task": 2,
        "init": {"seed_start": 0},
        "horizon": 12,
        "success": "any_step",
    }

    class Shown:
        """A policy that keeps what it is shown, by (episode, step)."""

        def __init__(self):
            self.images = {}

        def describe(self):
            return {"kind": "test"}

        def start(self, slot, episode):
            pass

        def end(self, slot, episode, result):
            pass

        def close(self):
            pass

        def act(self, requests):
            for r in requests:
                self.images[(r.episode.index, r.step)] = {k: np.array(r.observation[k]) for k in CAMERAS}
            return [np.full(7, 0.1 * ((r.episode.index % 3) - 1), np.float32) for r in requests]

    act = Shown()
    suite_python("robosuite")  # skips (or fails under ENVHUB_SUITES_REQUIRED) where it cannot be built
    results = evaluate(bench, act, num_envs=2, out=tmp_path / "out", record=tmp_path / "ds", progress=False)
    assert not any(e["error"] for e in results["episodes"]), [e["error"] for e in results["episodes"]]
    summary, data = load(tmp_path / "ds")
    keys = sorted(summary["video_keys"])
    assert keys == [f"observation.images.{c}" for c in CAMERAS], keys
    assert summary["episode_lengths"] == [12, 12] and summary["fps"] == 20, summary
    episodes = data["raw/episode_index"]
    for ep in np.unique(episodes):
        rows = np.flatnonzero(episodes == ep)
        # The evaluation episode whose first shown frame this is (the closest).
        first = data[keys[0]][rows[0]].astype(np.int16)
        k = min((0, 1), key=lambda k: np.abs(first - act.images[(k, 0)][CAMERAS[0]]).mean())
        for t, row in enumerate(rows):
            for camera, key in zip(CAMERAS, keys):
                decoded = data[key][row].astype(np.float64)
                error = np.abs(decoded - act.images[(k, t)][camera]).mean()
                assert error <= MEAN_ABS_TOLERANCE, (camera, k, t, error)
        assert float(data["raw/next.reward"][rows].sum()) == pytest.approx(
            next(e["return"] for e in results["episodes"] if e["index"] == k), rel=1e-9
        )


def test_the_command_line_records_and_says_where(tmp_path, policies):
    from harness import mujoco_or_skip

    mujoco_or_skip(envhub)
    done = run_cli(
        "mujoco", "--tasks", "mujoco-hopper", "--episodes", "2", "--policy", f"{policies}:zeros3",
        "--out", str(tmp_path / "o"), "--record", str(tmp_path / "ds"), "--quiet",
    )
    assert done.returncode == 0, done.stderr

    results = json.loads((tmp_path / "o" / "results.json").read_text())
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    lengths = [e["length"] for e in results["episodes"] if e["error"] is None]
    assert info["total_episodes"] == len(lengths) and info["total_frames"] == sum(lengths), (info, results["episodes"])
    assert results["run"]["dataset"]["path"] == str(tmp_path / "ds")
