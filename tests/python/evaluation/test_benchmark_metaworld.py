"""`envhub eval` on Meta-World against Meta-World's own evaluation.

Meta-World MT10 with Meta-World's scripted policies (`metaworld.policies`, run by
`envhub.evaluation.experts:metaworld` in the catalog's `metaworld` environment) through
envhub's evaluation equals `metaworld.evaluation.evaluation` run in-process in that
environment on `gym.make_vec("Meta-World/MT10", vector_strategy="sync", seed=1)`: per-task
success rates and per-episode returns, episode for episode (returns to float32's
precision, which the reference sums some of them in: see RETURN_REL). The
reference agent returns the scripted actions in the action space's dtype (float32), as the
envhub policy does.

Skipped where the `metaworld` environment cannot be built (`envhub env sync metaworld`);
failed instead under ENVHUB_SUITES_REQUIRED=1, as pyenv/test_suites.py does.
"""

from __future__ import annotations

import json
import os
import re
import subprocess

import numpy as np
import pytest
from harness import import_envhub, once_per_run

envhub = import_envhub()

from envhub.evaluation import evaluate  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_SUITES_REQUIRED"))
EPISODES = 3
SEED = 1
# Several tasks' rewards are sometimes an np.float32 (the others' are Python floats): from the
# first such step on, Gymnasium's RecordEpisodeStatistics (`episode_returns += reward`, under
# NumPy 2's promotion rules) sums the reference's return in float32. envhub carries every
# reward as float64 (a float32 value exactly) and sums in float64, so returns agree to
# float32's precision (relative 1e-5 over 500 steps); those summed in float64 on both sides
# agree bit for bit (counted below).
RETURN_REL = 1e-5

REFERENCE = """
import json, sys, warnings
import numpy as np
import gymnasium as gym
import metaworld
from metaworld.evaluation import evaluation, _get_task_names
from metaworld.policies import ENV_POLICY_MAP
warnings.simplefilter("ignore")

envs = gym.make_vec("Meta-World/MT10", vector_strategy="sync", seed=SEED)
names = _get_task_names(envs)
experts = [ENV_POLICY_MAP[n]() for n in names]

class Agent:
    def eval_action(self, obs):
        return np.stack([np.asarray(p.get_action(o), dtype=np.float32) for p, o in zip(experts, obs)])
    def reset(self, mask):
        pass

mean, _, rates, returns = evaluation(Agent(), envs, num_episodes=EPISODES)
print(json.dumps({"mean": mean, "rates": rates, "returns": returns}))
"""


def metaworld_python() -> str:
    from envhub._cli import BINARY

    done = subprocess.run([str(BINARY), "env", "sync", "metaworld"], capture_output=True, text=True, timeout=900)
    found = re.search(r"^metaworld: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
    if done.returncode != 0 or not found:
        reason = f"the Python environment `metaworld` cannot be built here: {(done.stderr or done.stdout)[-1500:]}"
        if REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_SUITES_REQUIRED is set")
        pytest.skip(reason)
    return os.path.join(found.group(1), "bin", "python")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Meta-World's own evaluation of MT10 (seed 1, EPISODES per task), run once for the
    test run (the test processes share it)."""
    python = metaworld_python()
    code = REFERENCE.replace("SEED", str(SEED)).replace("EPISODES", str(EPISODES))

    def run(_folder) -> dict:
        done = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        return json.loads(done.stdout.strip().splitlines()[-1])

    return once_per_run(tmp_path_factory, "metaworld-mt10-reference", run)


# One env runs every episode of every task in turn, switching tasks on reset; ten envs run
# them side by side, each switching as it takes the next episode: the table is the same.
@pytest.mark.parametrize("num_envs", [1, 10])
def test_mt10_scripted_equals_metaworld_evaluation(tmp_path, reference, num_envs):
    ref = reference
    results = evaluate(
        "metaworld-mt10",
        "envhub.evaluation.experts:metaworld",
        policy_env="metaworld",
        episodes=EPISODES,
        num_envs=num_envs,
        out=tmp_path / "mt10",
        progress=False,
    )
    assert results["summary"]["errors"] == 0, [e["error"] for e in results["episodes"] if e["error"]][:3]
    ours_returns: dict[str, list[float]] = {}
    for e in results["episodes"]:
        ours_returns.setdefault(e["task"].rsplit("/", 1)[-1], []).append(e["return"])
    ours_rates = {t["task"].rsplit("/", 1)[-1]: t["success_rate"] for t in results["per_task"]}
    assert set(ours_rates) == set(ref["rates"])
    exact = 0
    for task in ref["rates"]:
        assert ours_rates[task] == ref["rates"][task], task
        assert ours_returns[task] == pytest.approx(ref["returns"][task], rel=RETURN_REL), task
        exact += sum(a == b for a, b in zip(ours_returns[task], ref["returns"][task]))
    assert exact >= 1  # some tasks' returns are summed in float64 by both, and equal bit for bit
    assert results["summary"]["success_rate"] == pytest.approx(ref["mean"], abs=1e-12)
    # The episodes' initial conditions are the goals Meta-World's resets drew.
    assert [e["init"] for e in results["episodes"][:EPISODES]] == [
        {"goal": g} for g in envhub.evaluation.benchmarks.goal_draws(SEED, EPISODES)
    ]


def test_every_env_of_a_session_has_the_one_goal_set():
    """The adapter: every env of a session holds the goal set of the one seed (a train goal
    picked by index gives every env the same start); without one, env i draws its goals from
    its own generator, so the envs differ; a reset seed (ignored by Meta-World) changes nothing."""
    metaworld_python()
    envs = envhub.make_vec("metaworld-reach", 3, seed=3)
    try:
        picked, _ = envs.reset(options={"goal": 7})
        assert np.array_equal(picked[0], picked[1]) and np.array_equal(picked[0], picked[2])
        drawn, _ = envs.reset()
        assert not np.array_equal(drawn[0][36:39], drawn[1][36:39])  # goal positions differ
        again, _ = envs.reset(seed=[11, 12, 13], options={"goal": 7})
        assert np.array_equal(again, picked)
        with pytest.raises(envhub.EnvHubError, match="goal"):
            envs.reset(options={"goal": 50})
    finally:
        envs.close()


def test_reset_option_task_switches_an_env_to_another_task():
    """`reset(options={"task": t})`: an env (here the second of two, alone, by mask) runs task
    t from that reset on, starting as a session made for t starts (same goal set, seed and
    env index), and back; a name outside the benchmark's tasks is an error naming them."""
    metaworld_python()
    envs = envhub.make_vec("metaworld-reach", 2, seed=1, benchmark="MT10")
    push = envhub.make_vec("metaworld-reach", 2, seed=1, benchmark="MT10", env_name="push-v3")
    try:
        reach, _ = envs.reset(options={"goal": 4})
        pushed, _ = push.reset(options={"goal": 4})
        assert not np.array_equal(reach[1], pushed[1])
        mask = np.array([False, True])
        switched, _ = envs.reset(options={"goal": 4, "task": "push-v3", "reset_mask": mask})
        assert np.array_equal(switched[0], reach[0]) and np.array_equal(switched[1], pushed[1])
        # The same steps give the same observations as in push's own session.
        action = np.full((2, 4), 0.3, dtype=np.float32)
        for _ in range(5):
            ours, r1, *_ = envs.step(action)
            theirs, r2, *_ = push.step(action)
        assert np.array_equal(ours[1], theirs[1]) and r1[1] == r2[1]
        back, _ = envs.reset(options={"goal": 4, "task": "reach-v3"})
        assert np.array_equal(back, reach)
        # A task per env from the start: env i runs env_name[i], as in its task's own session.
        # With keep_tasks 1 an env closes the task it leaves, and makes it again on return.
        both = envhub.make_vec(
            "metaworld-reach", 2, seed=1, benchmark="MT10", env_name=["reach-v3", "push-v3"], keep_tasks=1
        )
        try:
            mixed, _ = both.reset(options={"goal": 4})
            assert np.array_equal(mixed[0], reach[0]) and np.array_equal(mixed[1], pushed[1])
            both.reset(options={"goal": 4, "task": "push-v3"})
            again, _ = both.reset(options={"goal": 4, "task": "reach-v3"})
            assert np.array_equal(again, reach)
        finally:
            both.close()
        with pytest.raises(envhub.EnvHubError, match=r"not a task of Meta-World's MT10; valid: push-v3, "):
            envs.reset(options={"task": "pussh-v3"})
        with pytest.raises(envhub.EnvHubError, match="valid: .*window-close-v3"):
            envs.reset(options={"task": "assembly-v3"})  # an MT50 task, not MT10's
    finally:
        envs.close()
        push.close()
