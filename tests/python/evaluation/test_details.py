"""The evaluation's smaller promises, each on a real env:

- a failed episode's error reaches stderr as it happens; with `--policy-env` it carries the
  policy's traceback from its process;
- `--out` is required on the command line (exit 2);
- a `done` during the settling steps is ignored, as the references' loops ignore it
  (Hopper falls and terminates while settling; its episode still gets its policy step);
- `--seeds N` runs the protocol under N seeds in `out/seed-<s>` and reports the spread;
- on Meta-World (no image observation) `--video` writes each episode's `render()` frames,
  and `versions` are those of the `metaworld` environment the workers ran in.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import evaluate  # noqa: E402
from envhub.evaluation.evaluate import evaluate_seeds, seeds_markdown  # noqa: E402
from envhub.evaluation.policy_env import EnvPolicy  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_SUITES_REQUIRED"))

PENDULUM = {
    "name": "pendulum",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 2,
    "init": {"seed_start": 10},
    "horizon": 5,
    "success": "none",
}

RAISES = textwrap.dedent(
    """\
    import numpy as np

    def explode(observations, tasks):
        return deeper(observations)

    def deeper(observations):
        raise ValueError("no model here")
    """
)


def test_errors_reach_stderr_and_keep_the_policy_process_traceback(tmp_path, capfd):
    (tmp_path / "raises.py").write_text(RAISES)
    policy = EnvPolicy(f"{tmp_path / 'raises.py'}:explode", [sys.executable], env_name="(this interpreter)")
    results = evaluate(PENDULUM, policy, out=tmp_path / "out", progress=False)
    error = results["episodes"][0]["error"]
    assert "the policy raised ValueError: no model here" in error
    assert "Traceback" in error and "in deeper" in error and "raises.py" in error
    err = capfd.readouterr().err
    assert "episode gym-pendulum#0 failed: the policy raised ValueError: no model here" in err
    assert "in deeper" in err  # the first time in full
    assert "episode gym-pendulum#1 failed: the policy raised ValueError: no model here (as above)" in err


def test_out_is_required_on_the_command_line(tmp_path):
    done = subprocess.run([sys.executable, "-m", "envhub.evaluation", "mujoco", "--policy", "x.py:act"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 2 and "give --out DIR" in done.stderr


def test_a_done_while_settling_is_ignored(tmp_path):
    gym = pytest.importorskip("gymnasium")
    push = [1.0, 1.0, 1.0]
    env = gym.make("Hopper-v5")
    env.reset(seed=3)
    fell = next((t for t in range(30) if env.step(np.array(push, np.float32))[2]), None)
    env.close()
    assert fell is not None  # the reference Hopper terminates while settling

    bench = {"name": "hopper", "entries": ["mujoco-hopper"], "episodes_per_task": 1, "init": {"seeds": [3]},
             "horizon": 4, "settle": {"steps": 30, "action": push}, "success": "none"}

    def still(observations, tasks):
        return np.zeros((len(observations), 3), np.float32)

    results = evaluate(bench, still, out=tmp_path / "out", progress=False)
    episode = results["episodes"][0]
    assert episode["error"] is None
    # The policy acted once, and that step ended it (the env is still down); before, the
    # episode ended at the fall with no policy step (length 0).
    assert episode["length"] == 1


def test_seeds_run_the_protocol_under_each_seed_and_report_the_spread(tmp_path):
    def act(observations, tasks):
        return np.stack([np.array([np.tanh(o[0])], np.float32) for o in observations])

    bench = {**PENDULUM, "success": {"rule": "last_step", "key": "never"}}
    summary = evaluate_seeds(bench, act, seeds=2, out=tmp_path / "seeds", progress=False)
    runs = [json.loads((tmp_path / "seeds" / f"seed-{s}" / "results.json").read_text()) for s in range(2)]
    assert [e["init"] for e in runs[0]["episodes"]] == [{"seed": 10}, {"seed": 11}]  # seed 0: the protocol
    assert [e["init"] for e in runs[1]["episodes"]] == [{"seed": 12}, {"seed": 13}]
    assert summary["spread"]["runs"] == 2 and summary["spread"]["mean"] == 0.0
    returns = [r["summary"]["mean_return"] for r in runs]
    assert summary["return_spread"]["mean"] == pytest.approx(sum(returns) / 2)
    assert json.loads((tmp_path / "seeds" / "seeds.json").read_text())["seeds"][1]["init"] == {"seed_start": 12}
    assert "seed 0 | seed 1 | mean | std" in seeds_markdown(summary)
    with pytest.raises(ValueError, match="no seed to vary"):
        evaluate_seeds({**bench, "init": {"seeds": [1, 2]}}, act, seeds=2, out=tmp_path / "fixed", progress=False)


def test_metaworld_videos_and_the_suite_versions(tmp_path):
    from envhub._cli import BINARY

    done = subprocess.run([str(BINARY), "env", "sync", "metaworld"], capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        reason = f"the Python environment `metaworld` cannot be built here: {(done.stderr or done.stdout)[-1500:]}"
        if REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_SUITES_REQUIRED is set")
        pytest.skip(reason)
    av = pytest.importorskip("av")
    results = evaluate("metaworld-mt1", "envhub.evaluation.experts:metaworld", policy_env="metaworld",
                       tasks=["reach-v3"], episodes=1, video=True, out=tmp_path / "mt1", progress=False)
    episode = results["episodes"][0]
    assert episode["error"] is None and episode["video"], episode
    with av.open(str(tmp_path / "mt1" / episode["video"])) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == episode["length"] + 1  # after settling (none here) and after each step
    assert frames[0].std() > 0  # a rendered scene, not a blank frame
    versions = results["versions"]
    assert versions["python_env"] == "metaworld"
    # The catalog's pins of that environment (configs/env_registry.yaml), not this interpreter's.
    assert versions["packages"]["metaworld"] == "3.1.1" and versions["packages"]["mujoco"] == "3.3.0"
    assert versions["packages"]["gymnasium"] == "1.2.0"
    assert versions["hub"]["packages"]["mujoco"] != "3.3.0"
