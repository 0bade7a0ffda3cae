"""The LeRobot plugin (`integrations/lerobot`, distribution `lerobot_env_envhub`) under LeRobot
0.6.1's own commands, in an interpreter with LeRobot and no suite: `--env.type=envhub`.

LeRobot's interpreter is `.venv-lerobot-next/` (`make lerobot-next`; `ENVHUB_LEROBOT_NEXT_PYTHON`
names another). The envhub wheel and the plugin's wheel are built once per run and installed
there as a user installs them (`pip install --target`, put on `PYTHONPATH`, so LeRobot's
interpreter stays as it is); the suites run in envhub's Python environments. LeRobot's own
envs are the reference: `lerobot[metaworld]` in a venv made once in the user cache (under a
lock, reused by later runs), from the same pins.

Without LeRobot's interpreter or the release build these tests skip, unless
`ENVHUB_LEROBOT_REQUIRED` is set (as `make py-test` does), when they fail.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import lerobot_envs
import numpy as np
import pytest
from harness import SUPPORT, once_per_run
from lerobot_envs import (
    LIBERO_FIRST,
    LIBERO_REFERENCE,
    METAWORLD_REFERENCE,
    Unavailable,
    libero_config,
    reference_venv,
    user_env,
)


def unavailable(message: str) -> None:
    if os.environ.get("ENVHUB_LEROBOT_REQUIRED"):
        pytest.fail(f"{message}, and ENVHUB_LEROBOT_REQUIRED is set")
    pytest.skip(message)


@pytest.fixture(scope="module")
def lerobot_python() -> Path:
    try:
        return lerobot_envs.lerobot_python()
    except Unavailable as e:
        unavailable(str(e))
        raise


@pytest.fixture(scope="module")
def plugin_site(lerobot_python: Path, tmp_path_factory) -> Path:
    """The envhub wheel and the plugin's wheel installed for LeRobot's interpreter, once
    per run (the test processes share it)."""
    try:
        made = once_per_run(
            tmp_path_factory, "lerobot-plugin-site", lambda folder: str(lerobot_envs.install_plugin(lerobot_python, folder))
        )
    except Unavailable as e:
        unavailable(str(e))
        raise
    return Path(made)


def reference(lerobot_python: Path, name: str, requirements: list[str], first: list[str] | None = None) -> Path:
    try:
        return reference_venv(lerobot_python, name, requirements, first)
    except Unavailable as e:
        unavailable(str(e))
        raise


def run(python: Path, args: list[str], site: Path | None, cwd: Path, timeout: int = 1500) -> str:
    """`python args` as a LeRobot user runs it (a reference venv's LIBERO config named)."""
    env = {**user_env(site), **libero_config(python)}
    done = subprocess.run([str(python), *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)
    assert done.returncode == 0, f"{args[:3]} exited {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-6000:]}"
    return done.stdout


def rollout(python: Path, site: Path | None, spec: dict, tmp: Path, name: str) -> dict[str, np.ndarray]:
    spec_file = tmp / f"{name}.json"
    spec_file.write_text(json.dumps(spec))
    out = tmp / f"{name}.npz"
    run(python, [str(SUPPORT / "lerobot_rollout.py"), str(spec_file), str(out)], site, tmp)
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def lerobot_eval(python: Path, site: Path | None, policy: Path, args: list[str], out: Path) -> dict:
    """The real `lerobot-eval` (its module, as its console script runs it): `eval_info.json`."""
    run(python, ["-m", "lerobot.scripts.lerobot_eval", f"--policy.path={policy}", *args, "--policy.device=cpu",
                 "--seed=1000", f"--output_dir={out}"], site, out.parent)
    return json.loads((out / "eval_info.json").read_text())


def per_episode(info: dict) -> list:
    """Each task's per-episode results in `eval_info.json` (without the video paths)."""
    keys = ("sum_rewards", "max_rewards", "successes")
    return [(t["task_group"], t["task_id"], [t["metrics"][k] for k in keys]) for t in info["per_task"]]


def assert_same_videos(mine: Path, theirs: Path, count: int) -> None:
    names = sorted(p.relative_to(mine) for p in mine.rglob("*.mp4"))
    assert len(names) == count and names == sorted(p.relative_to(theirs) for p in theirs.rglob("*.mp4")), names
    for name in names:
        assert (mine / name).read_bytes() == (theirs / name).read_bytes(), f"{name} differs"


def save_policy(python: Path, site: Path, spec: dict, folder: Path) -> Path:
    spec_file = folder.parent / f"{folder.name}.json"
    spec_file.write_text(json.dumps(spec))
    run(python, [str(SUPPORT / "lerobot_policy.py"), str(spec_file), str(folder)], site, folder.parent)
    return folder


# ---------------------------------------------------------------------------------------------

def test_ended_episode_frozen_as_lerobot_eval_freezes_it():
    """With asynchronous envs, `lerobot-eval` replays an ended episode's last transition
    (reward 0) instead of stepping or autoresetting the simulator, until a reset with
    `lerobot_new_rollout`; the LeRobot adapters do the same in the worker."""
    import gymnasium as gym
    from harness import import_envhub

    import_envhub()
    from envhub.worker.hosted.lerobot_rollout import NEW_ROLLOUT_OPTION, FrozenAfterEnd

    class Counting(gym.Env):
        observation_space = gym.spaces.Box(0, 100, (1,), np.float64)
        action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

        def __init__(self) -> None:
            self.t, self.steps, self.resets = 0, 0, 0

        def reset(self, *, seed=None, options=None):
            self.t, self.resets = 0, self.resets + 1
            return np.array([0.0]), {"reset": self.resets}

        def step(self, action):
            self.t, self.steps = self.t + 1, self.steps + 1
            return np.array([float(self.t)]), 1.0, self.t == 3, False, {"t": self.t}

    inner = Counting()
    env = FrozenAfterEnd(inner)
    env.reset(seed=0, options={NEW_ROLLOUT_OPTION: True})
    results = [env.step(np.zeros(1, np.float32)) for _ in range(3)]
    assert [r[2] for r in results] == [False, False, True] and results[-1][1] == 1.0
    obs, reward, terminated, truncated, info = env.step(np.zeros(1, np.float32))
    assert (obs.tolist(), reward, terminated, truncated, info, inner.steps) == ([3.0], 0.0, True, False, {"t": 3}, 3)
    obs, info = env.reset()  # Gymnasium's autoreset: no inner reset
    assert (obs.tolist(), info, inner.resets) == ([3.0], {"t": 3}, 1)
    obs, info = env.reset(seed=1, options={NEW_ROLLOUT_OPTION: True})
    assert (obs.tolist(), inner.resets) == ([0.0], 2)
    assert env.step(np.zeros(1, np.float32))[0].tolist() == [1.0]


PLUGIN_CHECK = r"""
import importlib.util, json
from lerobot.utils.import_utils import register_third_party_plugins
register_third_party_plugins()
from lerobot.envs.configs import EnvConfig, LiberoEnv, MetaworldEnv
from lerobot.envs.factory import make_env_config
out = {"types": sorted(EnvConfig.get_known_choices()),
       "suites_here": [m for m in ("libero", "metaworld", "robosuite") if importlib.util.find_spec(m)]}
def same(mine, theirs):
    return {"features": {k: [str(v.type), list(v.shape)] for k, v in mine.features.items()} ==
                        {k: [str(v.type), list(v.shape)] for k, v in theirs.features.items()},
            "features_map": mine.features_map == theirs.features_map, "fps": [mine.fps, theirs.fps]}
out["libero"] = same(make_env_config("envhub", task="libero_spatial"), LiberoEnv(task="libero_spatial"))
out["libero_128"] = same(make_env_config("envhub", task="libero-10", observation_height=128, observation_width=128),
                         LiberoEnv(task="libero_10", observation_height=128, observation_width=128))
out["metaworld"] = same(make_env_config("envhub", task="metaworld-push"), MetaworldEnv(task="push-v3"))
hopper = make_env_config("envhub", task="mujoco-hopper")
out["hopper"] = {k: [str(v.type), list(v.shape)] for k, v in hopper.features.items()}
out["hopper_map"] = hopper.features_map
out["processors"] = [type(s).__name__ for s in make_env_config("envhub", task="libero_goal").get_env_processors()[0].steps]
envs = make_env_config("envhub", task="metaworld-mt10").create_envs(2)
out["mt10"] = {g: sorted(t) for g, t in envs.items()}
out["mt10_task"] = [e.call("task_description")[0] for e in envs["metaworld-mt10"].values()][:2]
spatial = make_env_config("envhub", task="libero_spatial", task_ids=[3, 1]).create_envs(2)
out["spatial"] = {g: sorted(t) for g, t in spatial.items()}
try:
    make_env_config("envhub", task="mujoco-hoper")
except Exception as e:
    out["error"] = str(e)
print("RESULT" + json.dumps(out))
"""


def test_plugin_registers_with_lerobots_features(lerobot_python, plugin_site, tmp_path):
    """LeRobot finds `envhub` among its env types; LIBERO's and Meta-World's features,
    `features_map`, fps and env processors are those of LeRobot's own configs; another entry's
    come from its spaces; a wrong task names the closest ones. Nothing starts a suite."""
    out = run(lerobot_python, ["-c", PLUGIN_CHECK], plugin_site, tmp_path, timeout=600)
    result = json.loads(out.split("RESULT", 1)[1])
    assert "envhub" in result["types"] and "libero" in result["types"]
    assert result["suites_here"] == []
    for name in ("libero", "libero_128", "metaworld"):
        assert result[name]["features"] and result[name]["features_map"], result[name]
        assert result[name]["fps"][0] == result[name]["fps"][1]
    assert result["hopper"] == {"action": ["FeatureType.ACTION", [3]], "agent_pos": ["FeatureType.STATE", [11]]}
    assert result["hopper_map"] == {"action": "action", "agent_pos": "observation.state"}
    assert result["processors"] == ["LiberoProcessorStep"]
    assert result["mt10"] == {"metaworld-mt10": list(range(10))}
    assert result["mt10_task"] == ["Reach a goal position", "Push the puck to a goal"]
    assert result["spatial"] == {"libero_spatial": [1, 3]}
    assert "mujoco-hopper" in result["error"]


# slow: 4 rollouts of 100 steps of 2 envs rendering 480x480 frames, each in a fresh LeRobot interpreter
@pytest.mark.slow
def test_metaworld_same_episodes_as_lerobots_env(lerobot_python, plugin_site, tmp_path):
    """LeRobot's `--env.type=metaworld` (metaworld 3.0.0 in LeRobot's interpreter) and
    `--env.type=envhub` (Meta-World in envhub's environment): the same first observations
    after LeRobot's preprocessing and the same frames from `render`, bit for bit; a fixed
    action sequence gives the same rewards, ends, `is_success` and observations. Both with
    LeRobot's synchronous envs and with its asynchronous ones (ended episodes frozen)."""
    reference_python = reference(lerobot_python, "metaworld", METAWORLD_REFERENCE)
    for asynchronous in (False, True):
        spec = {"n_envs": 2, "seeds": [10, 11], "steps": 100, "async": asynchronous}
        theirs = rollout(reference_python, None, {**spec, "type": "metaworld", "config": {"task": "push-v3"}}, tmp_path, f"ref{asynchronous}")
        mine = rollout(lerobot_python, plugin_site, {**spec, "type": "envhub", "config": {"task": "push-v3"}}, tmp_path, f"mine{asynchronous}")
        assert sorted(theirs) == sorted(mine)
        for key in theirs:
            assert theirs[key].dtype == mine[key].dtype, key
            assert np.array_equal(theirs[key], mine[key]), key
        assert set(theirs["first/observation.image"].shape) == {2, 3, 480}
        assert theirs["rewards"].std() > 0


# slow: LIBERO's hard resets and 40 steps of 2 envs in each of two fresh interpreters
@pytest.mark.slow
def test_libero_same_episodes_as_lerobots_env(lerobot_python, plugin_site, tmp_path):
    """LeRobot's `--env.type=libero` (`lerobot[libero]` in LeRobot's interpreter) and
    `--env.type=envhub` (LIBERO in envhub's environment pinned as that install): the same
    first observations after LeRobot's preprocessing (its `LiberoProcessorStep`), the same
    `render` frames, the same rewards, ends, `is_success` and observations for a fixed action
    sequence, from the task's fixed initial states 0 and 1 (128x128 cameras)."""
    reference_python = reference(lerobot_python, "libero", LIBERO_REFERENCE, LIBERO_FIRST)
    config = {"task": "libero_spatial", "task_ids": [0], "observation_height": 128, "observation_width": 128}
    spec = {"n_envs": 2, "seeds": [10, 11], "steps": 40, "config": config}
    theirs = rollout(reference_python, None, {**spec, "type": "libero"}, tmp_path, "ref")
    mine = rollout(lerobot_python, plugin_site, {**spec, "type": "envhub"}, tmp_path, "mine")
    assert sorted(theirs) == sorted(mine)
    for key in theirs:
        assert theirs[key].dtype == mine[key].dtype, key
        assert np.array_equal(theirs[key], mine[key]), key
    assert theirs["first/observation.state"].shape == (2, 8)
    assert int(theirs["max_episode_steps"][0]) == 280


# slow: 2 episodes of 500 steps through lerobot-eval, videos included
@pytest.mark.slow
def test_lerobot_eval_metaworld_end_to_end(lerobot_python, plugin_site, tmp_path):
    """The real `lerobot-eval` (its module, as its console script runs it) evaluates a
    saved random-init ACT policy on a Meta-World task through `--env.type=envhub`, 2 episodes
    in a batch of 2 asynchronous envs, in an interpreter with no Meta-World: eval_info.json
    has both episodes and the videos were written from `render`."""
    policy = save_policy(lerobot_python, plugin_site, {"type": "envhub", "config": {"task": "push-v3"}}, tmp_path / "policy")
    out = tmp_path / "eval"
    args = ["--env.type=envhub", "--env.task=push-v3", "--eval.n_episodes=2", "--eval.batch_size=2"]
    info = lerobot_eval(lerobot_python, plugin_site, policy, args, out)
    episodes = info["per_task"][0]["metrics"] if "per_task" in info else None
    assert episodes is not None, info.keys()
    assert len(episodes["successes"]) == 2
    assert len(list((out / "videos").rglob("*.mp4"))) == 2


TINY_DATASET = r"""
import sys
import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
features = {
    "observation.image": {"dtype": "image", "shape": (480, 480, 3), "names": ["height", "width", "channels"]},
    "observation.state": {"dtype": "float32", "shape": (4,), "names": None},
    "action": {"dtype": "float32", "shape": (4,), "names": None},
}
ds = LeRobotDataset.create("envhub/tiny", fps=80, features=features, root=sys.argv[1], use_videos=False)
rng = np.random.default_rng(0)
for episode in range(2):
    for _ in range(8):
        ds.add_frame({"observation.image": rng.integers(0, 256, (480, 480, 3), dtype=np.uint8),
                      "observation.state": rng.standard_normal(4).astype(np.float32),
                      "action": rng.uniform(-1, 1, 4).astype(np.float32), "task": "Push the puck to a goal"})
    ds.save_episode()
ds.finalize()
"""


# slow: LeRobot's training start-up, then an evaluation episode (20 steps) in a fresh worker
@pytest.mark.slow
def test_lerobot_train_evaluates_through_envhub(lerobot_python, plugin_site, tmp_path):
    """`lerobot-train --env.type=envhub` runs its periodic evaluation on a Meta-World task
    (a tiny ACT trained two steps on a tiny local dataset, evaluated after the second, one
    episode cut at 20 steps by `--env.episode_length`): the evaluation's video is written."""
    data = tmp_path / "data"
    run(lerobot_python, ["-c", TINY_DATASET, str(data)], plugin_site, tmp_path)
    out = tmp_path / "train"
    policy = ["--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false",
              "--policy.pretrained_backbone_weights=null", "--policy.dim_model=32", "--policy.n_heads=2",
              "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1",
              "--policy.use_vae=false", "--policy.chunk_size=10", "--policy.n_action_steps=10"]
    args = ["--dataset.repo_id=envhub/tiny", f"--dataset.root={data}", *policy, "--env.type=envhub",
            "--env.task=push-v3", "--env.episode_length=20", "--steps=2", "--env_eval_freq=2", "--eval.n_episodes=1", "--eval.batch_size=1",
            "--batch_size=2", "--num_workers=0", "--save_checkpoint=false", "--wandb.enable=false",
            f"--output_dir={out}", "--log_freq=1"]
    done = subprocess.run(
        [str(lerobot_python), "-m", "lerobot.scripts.lerobot_train", *args],
        capture_output=True, text=True, timeout=1500, cwd=tmp_path, env=user_env(plugin_site),
    )
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-6000:]
    assert "Eval policy at step 2" in log, log[-4000:]
    assert list((out / "eval").rglob("*.mp4")), log[-4000:]


# slow: LIBERO's hard resets and 30 steps of 2 envs through lerobot-eval, twice (envhub, LeRobot's env)
@pytest.mark.slow
def test_lerobot_eval_libero_end_to_end(lerobot_python, plugin_site, tmp_path):
    """`lerobot-eval --env.type=envhub --env.task=libero_spatial` (task 0, 128x128 cameras,
    LeRobot's `--env.episode_length=30`, 2 episodes in a batch of 2) in an interpreter with no
    LIBERO, and the same command with `--env.type=libero` where `lerobot[libero]` is installed:
    the same per-episode results in `eval_info.json` and the same videos, byte for byte (the
    policy's closed loop saw the same frames through either)."""
    reference_python = reference(lerobot_python, "libero", LIBERO_REFERENCE, LIBERO_FIRST)
    config = {"task": "libero_spatial", "task_ids": [0], "observation_height": 128, "observation_width": 128}
    policy = save_policy(lerobot_python, plugin_site, {"type": "envhub", "config": config}, tmp_path / "policy")
    args = ["--env.task=libero_spatial", "--env.task_ids=[0]", "--env.observation_height=128",
            "--env.observation_width=128", "--env.episode_length=30", "--eval.n_episodes=2", "--eval.batch_size=2"]
    mine = lerobot_eval(lerobot_python, plugin_site, policy, ["--env.type=envhub", *args], tmp_path / "mine")
    theirs = lerobot_eval(reference_python, None, policy, ["--env.type=libero", *args], tmp_path / "theirs")
    (task,) = mine["per_task"]
    assert (task["task_group"], task["task_id"]) == ("libero_spatial", 0)
    assert len(task["metrics"]["successes"]) == 2
    assert per_episode(mine) == per_episode(theirs)
    assert_same_videos(tmp_path / "mine", tmp_path / "theirs", 2)
