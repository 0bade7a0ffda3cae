"""The LeRobot plugin (`integrations/lerobot`, distribution `lerobot_env_envhub`) under LeRobot
0.6.1's own commands, in an interpreter with LeRobot and no suite: `--env.type=envhub`.

LeRobot's interpreter is `.venv-lerobot/` (`make lerobot`; `ENVHUB_LEROBOT_PYTHON` names
another). The envhub wheel and the plugin's wheel are built once per run and installed
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
    """`python args` as a LeRobot user runs it (a reference venv's LIBERO config named): its
    stdout, then its stderr."""
    env = {**user_env(site), **libero_config(python)}
    done = subprocess.run([str(python), *args], capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)
    assert done.returncode == 0, f"{args[:3]} exited {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-6000:]}"
    return done.stdout + done.stderr


def run_steps(python: Path, site: Path | None, folder: Path, steps: list[list]) -> str:
    """`steps` in one LeRobot interpreter, in `folder` (see `lerobot_steps.py`: save a policy,
    roll out fixed actions, the real `lerobot-eval` or `lerobot-train`); a step's spec given as
    a dict is written to a file beside it."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for number, (kind, *args) in enumerate(steps):
        if args and isinstance(args[0], dict):
            spec = folder / f"{number}-{kind}.json"
            spec.write_text(json.dumps(args[0]))
            args = [spec, *args[1:]]
        written.append([kind, *map(str, args)])
    (folder / "steps.json").write_text(json.dumps(written))
    return run(python, [str(SUPPORT / "lerobot_steps.py"), str(folder / "steps.json")], site, folder)


def eval_args(policy: Path, args: list[str], out: Path) -> list[str]:
    """`lerobot-eval`'s arguments: the saved policy on the CPU, seed 1000, output to `out`."""
    return [f"--policy.path={policy}", *args, "--policy.device=cpu", "--seed=1000", f"--output_dir={out}"]


def both_sides(lerobot_python: Path, site: Path, reference_python: Path, folder: Path, suite: str,
               config: dict, rollout_spec: dict, args: list[str], reference_eval: bool = True) -> dict[str, Path]:
    """The plugin's side (`--env.type=envhub`, LeRobot's interpreter with the plugin) and
    LeRobot's own (`--env.type=<suite>`, the reference venv), one interpreter each: the same
    fixed-action rollout (`rollout.npz`) and the same `lerobot-eval` command (`eval/`; on
    LeRobot's side only with `reference_eval`) of a random-init ACT that the plugin's side
    saves first. Returns each side's folder."""
    policy = folder / "policy"
    sides = {"mine": (lerobot_python, site, "envhub"), "theirs": (reference_python, None, suite)}
    for side, (python, side_site, env_type) in sides.items():
        steps: list[list] = [["policy", {"type": "envhub", "config": config}, policy]] if side == "mine" else []
        steps.append(["rollout", {**rollout_spec, "type": env_type, "config": config}, folder / side / "rollout.npz"])
        if side == "mine" or reference_eval:
            steps.append(["eval", *eval_args(policy, [f"--env.type={env_type}", *args], folder / side / "eval")])
        run_steps(python, side_site, folder / side, steps)
    return {side: folder / side for side in sides}


def same_rollouts(runs: dict[str, Path]) -> dict[str, np.ndarray]:
    """Asserts both sides' rollouts equal, array by array, dtype and bits; returns LeRobot's."""
    with np.load(runs["theirs"] / "rollout.npz") as t, np.load(runs["mine"] / "rollout.npz") as m:
        theirs, mine = {k: t[k] for k in t.files}, {k: m[k] for k in m.files}
    assert sorted(theirs) == sorted(mine)
    for key in theirs:
        assert theirs[key].dtype == mine[key].dtype, key
        assert np.array_equal(theirs[key], mine[key]), key
    return theirs


def per_episode(info: dict) -> list:
    """Each task's per-episode results in `eval_info.json` (without the video paths)."""
    keys = ("sum_rewards", "max_rewards", "successes")
    return [(t["task_group"], t["task_id"], [t["metrics"][k] for k in keys]) for t in info["per_task"]]


def same_evaluations(runs: dict[str, Path], videos: int) -> dict:
    """Asserts both sides' `eval_info.json` per-episode results equal and their videos equal
    byte for byte; returns the plugin's `eval_info.json`."""
    mine, theirs = (json.loads((runs[s] / "eval" / "eval_info.json").read_text()) for s in ("mine", "theirs"))
    assert per_episode(mine) == per_episode(theirs)
    names = sorted(p.relative_to(runs["mine"] / "eval") for p in (runs["mine"] / "eval").rglob("*.mp4"))
    assert len(names) == videos, names
    assert names == sorted(p.relative_to(runs["theirs"] / "eval") for p in (runs["theirs"] / "eval").rglob("*.mp4"))
    for name in names:
        assert (runs["mine"] / "eval" / name).read_bytes() == (runs["theirs"] / "eval" / name).read_bytes(), name
    return mine


# ---------------------------------------------------------------------------------------------

def test_default_workers_keep_every_core_busy_through_a_lock_step_batch():
    """LeRobot's rollout waits for a batch's slowest worker: the default worker count is the
    fewest whose largest share of envs is within 10% of envs / cores (`workers.py`)."""
    import importlib.util

    path = Path(__file__).resolve().parents[3] / "integrations" / "lerobot" / "lerobot_env_envhub" / "workers.py"
    spec = importlib.util.spec_from_file_location("plugin_workers", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    balanced = module.balanced_workers
    # (envs, cores) -> workers: an even split keeps one per core; 5 on 2 takes 3 (2, 2, 1) as
    # 2 cores allow 2.5 env-steps a batch, where 2 workers take 3; never more than one per env.
    cases = {(5, 2): 3, (4, 2): 2, (16, 2): 2, (3, 2): 3, (1, 8): 1, (2, 8): 2, (15, 8): 8, (10, 4): 5, (100, 16): 17}
    assert {case: balanced(*case) for case in cases} == cases
    for envs in range(1, 40):
        for cores in (1, 2, 3, 4, 8, 16):
            workers = balanced(envs, cores)
            assert min(envs, cores) <= workers <= envs
            assert -(-envs // workers) <= 1.1 * max(1.0, envs / cores), (envs, cores, workers)
    for bad in ((0, 2), (4, 0)):
        with pytest.raises(ValueError):
            balanced(*bad)


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
    result = json.loads(out.split("RESULT", 1)[1].splitlines()[0])
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


# Each suite's runs, shared by its two tests (one worker runs both under xdist): the plugin's
# side and LeRobot's own, one interpreter each (`both_sides`).
METAWORLD_TASK = "metaworld-push-v3"
METAWORLD = pytest.mark.xdist_group("lerobot-metaworld")
LIBERO = pytest.mark.xdist_group("lerobot-libero")
LIBERO_CONFIG = {"task": "libero_spatial", "task_ids": [0], "observation_height": 128, "observation_width": 128}


#: Where `lerobot-eval`'s Meta-World episodes stop (`--env.episode_length`; LeRobot's own 500).
METAWORLD_EVAL_STEPS = 60


@pytest.fixture(scope="module")
def metaworld_runs(lerobot_python, plugin_site, tmp_path_factory) -> dict[str, Path]:
    """Meta-World's push task: 100 fixed-action steps of 2 synchronous envs on both sides, and
    `lerobot-eval` of 2 episodes cut at 60 steps by `--env.episode_length` in a batch of 2
    asynchronous envs through the plugin. Not through LeRobot's own env, which stops at
    Meta-World's 500 steps whatever `episode_length` says: its 1,000 steps, each drawing its
    480x480 frame twice (observation and `render`), took over 25 minutes on a busy 2-core
    machine, more than this suite's other LeRobot tests together."""
    reference_python = reference(lerobot_python, "metaworld", METAWORLD_REFERENCE)
    return both_sides(
        lerobot_python, plugin_site, reference_python, tmp_path_factory.mktemp("metaworld"), "metaworld",
        {"task": METAWORLD_TASK}, {"n_envs": 2, "seeds": [10, 11], "steps": 100},
        [f"--env.task={METAWORLD_TASK}", f"--env.episode_length={METAWORLD_EVAL_STEPS}", "--eval.n_episodes=2",
         "--eval.batch_size=2"],
        reference_eval=False,
    )


@pytest.fixture(scope="module")
def libero_runs(lerobot_python, plugin_site, tmp_path_factory) -> dict[str, Path]:
    """LIBERO's libero_spatial task 0 (128x128 cameras): 40 fixed-action steps of 2 synchronous
    envs, and `lerobot-eval` of 2 episodes cut at 30 steps by LeRobot's `--env.episode_length`,
    in a batch of 2 asynchronous envs."""
    reference_python = reference(lerobot_python, "libero", LIBERO_REFERENCE, LIBERO_FIRST)
    args = ["--env.task=libero_spatial", "--env.task_ids=[0]", "--env.observation_height=128",
            "--env.observation_width=128", "--env.episode_length=30", "--eval.n_episodes=2", "--eval.batch_size=2"]
    return both_sides(
        lerobot_python, plugin_site, reference_python, tmp_path_factory.mktemp("libero"), "libero",
        LIBERO_CONFIG, {"n_envs": 2, "seeds": [10, 11], "steps": 40}, args,
    )


# slow: the Meta-World runs (metaworld_runs): 100 steps of 480x480 frames on each side, 120 in lerobot-eval
@pytest.mark.slow
@METAWORLD
def test_metaworld_same_episodes_as_lerobots_env(metaworld_runs):
    """LeRobot's `--env.type=metaworld` (metaworld 3.0.0 in LeRobot's interpreter) and
    `--env.type=envhub` (Meta-World in envhub's environment): the same first observations
    after LeRobot's preprocessing and the same frames from `render`, bit for bit; a fixed
    action sequence gives the same rewards, ends, `is_success` and observations. (LeRobot's
    asynchronous envs differ from its synchronous ones only once an episode ends, which no
    episode does in these 100 steps: the `lerobot-eval` test runs them, to its episodes' ends.)"""
    theirs = same_rollouts(metaworld_runs)
    assert set(theirs["first/observation.image"].shape) == {2, 3, 480}
    assert theirs["rewards"].std() > 0


# slow: as test_metaworld_same_episodes_as_lerobots_env, whose runs it shares
@pytest.mark.slow
@METAWORLD
def test_lerobot_eval_metaworld_end_to_end(metaworld_runs):
    """The real `lerobot-eval` (as its console script runs it) evaluates a saved random-init
    ACT policy on Meta-World's push task through `--env.type=envhub`, 2 episodes in a batch of
    2 asynchronous envs cut at 60 steps by `--env.episode_length`, in an interpreter with no
    Meta-World: `eval_info.json` has both episodes, and the videos were written from `render`,
    a 480x480 frame per step up to each episode's end (the horizon, or success before it)."""
    import av

    out = metaworld_runs["mine"] / "eval"
    info = json.loads((out / "eval_info.json").read_text())
    (task,) = info["per_task"]
    assert (task["task_group"], task["task_id"]) == (METAWORLD_TASK, 0)
    assert len(task["metrics"]["successes"]) == 2 and len(task["metrics"]["sum_rewards"]) == 2
    videos = sorted((out / "videos").rglob("*.mp4"))
    assert len(videos) == 2
    for video, success in zip(videos, task["metrics"]["successes"]):
        with av.open(str(video)) as container:
            frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        assert frames[0].shape == (480, 480, 3)
        assert (len(frames) <= METAWORLD_EVAL_STEPS) if success else (len(frames) == METAWORLD_EVAL_STEPS), len(frames)


# slow: both sides' LIBERO runs (libero_runs): LIBERO's hard resets, 70 steps of 2 envs each
@pytest.mark.slow
@LIBERO
def test_libero_same_episodes_as_lerobots_env(libero_runs):
    """LeRobot's `--env.type=libero` (`lerobot[libero]` in LeRobot's interpreter) and
    `--env.type=envhub` (LIBERO in envhub's environment pinned as that install): the same
    first observations after LeRobot's preprocessing (its `LiberoProcessorStep`), the same
    `render` frames, the same rewards, ends, `is_success` and observations for a fixed action
    sequence, from the task's fixed initial states 0 and 1 (128x128 cameras)."""
    theirs = same_rollouts(libero_runs)
    assert theirs["first/observation.state"].shape == (2, 8)
    assert int(theirs["max_episode_steps"][0]) == 280


# slow: as test_libero_same_episodes_as_lerobots_env, whose runs it shares
@pytest.mark.slow
@LIBERO
def test_lerobot_eval_libero_end_to_end(libero_runs):
    """`lerobot-eval --env.type=envhub --env.task=libero_spatial` (task 0, 128x128 cameras,
    LeRobot's `--env.episode_length=30`, 2 episodes in a batch of 2) in an interpreter with no
    LIBERO, and the same command with `--env.type=libero` where `lerobot[libero]` is installed:
    the same per-episode results in `eval_info.json` and the same videos, byte for byte (the
    policy's closed loop saw the same frames through either)."""
    info = same_evaluations(libero_runs, 2)
    (task,) = info["per_task"]
    assert (task["task_group"], task["task_id"]) == ("libero_spatial", 0)
    assert len(task["metrics"]["successes"]) == 2


# slow: a tiny dataset, LeRobot's training start-up, then an evaluation episode (20 steps) in a fresh worker
@pytest.mark.slow
def test_lerobot_train_evaluates_through_envhub(lerobot_python, plugin_site, tmp_path):
    """`lerobot-train --env.type=envhub` (as its console script runs it) runs its periodic
    evaluation on a Meta-World task (a tiny ACT trained two steps on a tiny local dataset,
    evaluated after the second, one episode cut at 20 steps by `--env.episode_length`): the
    evaluation's video is written."""
    data, out = tmp_path / "data", tmp_path / "train"
    policy = ["--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false",
              "--policy.pretrained_backbone_weights=null", "--policy.dim_model=32", "--policy.n_heads=2",
              "--policy.dim_feedforward=64", "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1",
              "--policy.use_vae=false", "--policy.chunk_size=10", "--policy.n_action_steps=10"]
    args = ["--dataset.repo_id=envhub/tiny", f"--dataset.root={data}", *policy, "--env.type=envhub",
            "--env.task=push-v3", "--env.episode_length=20", "--steps=2", "--env_eval_freq=2", "--eval.n_episodes=1", "--eval.batch_size=1",
            "--batch_size=2", "--num_workers=0", "--save_checkpoint=false", "--wandb.enable=false",
            f"--output_dir={out}", "--log_freq=1"]
    log = run_steps(lerobot_python, plugin_site, tmp_path / "steps", [["dataset", data], ["train", *args]])
    assert "Eval policy at step 2" in log, log[-4000:]
    assert list((out / "eval").rglob("*.mp4")), log[-4000:]
