"""`envhub.evaluation` on fast native envs (Pendulum, through real workers and shared memory).

- The built-in benchmarks parse and `--list` shows them; an unknown benchmark, task or
  protocol field is an error naming the valid ones, closest first (exit status 2).
- Each episode's result depends only on (benchmark, task, episode index, policy): the same
  table with 1 env or 3, action chunks and replanning included.
- A policy's bad answers (wrong shape, a dtype that is not a number, NaN) fail their episode
  with an error naming the action space; an exception fails its batch's episodes; the rest
  runs on; `fail_fast` stops.
- Results are durable: an evaluation stopped midway resumes with every episode run once,
  and the resumed table equals an uninterrupted run's.
- A policy in another interpreter (the pipe protocol) gives the same results as in-process.
"""

from __future__ import annotations

import json
import sys
import textwrap
import time

import numpy as np
import pytest
from eval_policies import (
    policies,  # noqa: F401 - a fixture
    run_cli,
    table,
)
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import BenchmarkError, CallablePolicy, EvaluationStopped, evaluate  # noqa: E402
from envhub.evaluation.benchmarks import parse  # noqa: E402
from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.protocol import Observer, check_actions, resize_with_pad  # noqa: E402

PENDULUM = {
    "name": "pendulum",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 5,
    "init": {"seed_start": 10},
    "horizon": 30,
    "settle": {"steps": 3, "action": [0.5]},
    "success": "none",
}


# The catalog -----------------------------------------------------------------------------------


def test_builtin_benchmarks_parse_with_the_reference_protocols():
    catalog = Catalog()
    names = catalog.names()
    for name in ("libero-spatial", "libero-object", "libero-goal", "libero-10", "libero-90", "metaworld-mt10",
                 "metaworld-mt50", "metaworld-mt1", "robosuite", "maniskill-pick-cube", "dm-control", "mujoco"):
        assert name in names
    benches = {n: catalog.get(n) for n in names}  # every one checks against the catalog's entries
    horizons = {n: benches[f"libero-{n}"].horizon for n in ("spatial", "object", "goal", "10", "90")}
    assert horizons == {"spatial": 220, "object": 280, "goal": 300, "10": 520, "90": 400}
    for n in ("spatial", "object", "goal", "10", "90"):
        b = benches[f"libero-{n}"]
        assert (b.settle_steps, b.settle_action, b.episodes_per_task) == (10, [0, 0, 0, 0, 0, 0, -1], 50)
        assert b.rule == "any_step" and b.episode_init(3) == {"init_state": 3, "seed": 7}
    assert len(benches["libero-90"].tasks) == 90
    mt10, mt50 = benches["metaworld-mt10"], benches["metaworld-mt50"]
    assert (len(mt10.tasks), len(mt50.tasks), mt10.horizon, mt10.rule) == (10, 50, 500, "any_step")
    assert mt10.env_options(mt10.tasks[0]) == {"env_name": "reach-v3", "benchmark": "MT10", "seed": 1}
    # Meta-World's envs switch tasks on reset: one session runs every task.
    assert mt10.reset_options(mt10.tasks[1]) == {"task": "push-v3"}
    assert mt10.session_options(mt10.tasks[:2])["env_name"] == ["reach-v3", "push-v3"]  # env i's first task
    assert benches["libero-10"].reset_options(benches["libero-10"].tasks[1]) == {}
    assert benches["dm-control"].rule == "none" and benches["mujoco"].rule == "none"


def test_list_shows_the_benchmarks():
    done = run_cli("--list", "--json")
    assert done.returncode == 0, done.stderr
    rows = {r["name"]: r for r in json.loads(done.stdout)}
    assert rows["libero-10"]["horizon"] == 520 and rows["metaworld-mt10"]["tasks"] == 10


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["libero-spatail", "--policy", "x:y"], "unknown benchmark `libero-spatail`; valid: `libero-spatial`"),
        (["metaworld-mt10", "--tasks", "reach-v2", "--policy", "x:y"], "valid: `metaworld-mt10/reach-v3`"),
        (["libero-10", "--episodes", "0", "--policy", "x:y"], "--episodes must be at least 1"),
        (["libero-10"], "give --policy module:function or --server URL"),
    ],
)
def test_usage_errors_name_the_valid_choices(args, expected):
    done = run_cli(*args)
    assert done.returncode == 2, done.stderr
    assert expected in done.stderr


@pytest.mark.parametrize(
    ("decl", "expected"),
    [
        ({**PENDULUM, "horizn": 3}, "unknown field of benchmark `b` `horizn`; valid: `horizon`"),
        ({**PENDULUM, "success": {"rule": "anystep"}}, "unknown success rule in benchmark `b` `anystep`; valid: `any_step`"),
        ({**PENDULUM, "init": {"seed": 3}}, "valid: `seeds`, `seed_start`"),
        ({**PENDULUM, "entries": ["gym-pendulm"]}, "valid: `gym-pendulum`"),
        ({**PENDULUM, "settle": {"steps": 2, "action": [float("nan")]}}, "`settle.action` must be a list of finite numbers"),
        ({**PENDULUM, "episodes_per_task": 0}, "`episodes_per_task` must be an integer >= 1"),
        ({**PENDULUM, "init": {"seeds": [1, 2]}}, "5 episodes per task but 2 seeds"),
        ({**PENDULUM, "task_reset_option": "task"}, "`tasks`/`task_option`/`task_reset_option`/`axes` go with `entry`"),
        ({**{k: v for k, v in PENDULUM.items() if k != "entries"}, "entry": "gym-pendulum", "task_reset_option": "task"},
         "`task_reset_option` switches between `tasks`; this benchmark lists none"),
    ],
)
def test_protocol_fields_are_checked(decl, expected):
    decl = {k: v for k, v in decl.items() if k != "name"}
    with pytest.raises(BenchmarkError) as e:
        parse("b", decl, set(Catalog().registry.list_ids()))
    assert expected in str(e.value)


# Protocol pieces -------------------------------------------------------------------------------


def test_observation_transforms_flip_and_pad_resize():
    import gymnasium as gym

    space = gym.spaces.Dict(
        {"cam": gym.spaces.Box(0, 255, (4, 8, 3), np.uint8), "state": gym.spaces.Box(-1, 1, (2,), np.float64)}
    )
    image = np.arange(4 * 8 * 3, dtype=np.uint8).reshape(4, 8, 3)
    obs = {"cam": image, "state": np.zeros(2)}
    shown = Observer({"keys": ["cam"], "flip": ["cam"]}, space)(obs)
    assert list(shown) == ["cam"] and np.array_equal(shown["cam"], image[::-1, ::-1])
    padded = resize_with_pad(image, 8, 8)
    assert padded.shape == (8, 8, 3)
    assert not padded[:2].any() and not padded[6:].any() and padded[2:6].any()  # black bars, centred
    assert np.array_equal(padded[2:6], image)  # same size: copied, not resampled
    with pytest.raises(BenchmarkError, match="valid: `cam`"):
        Observer({"keys": ["cma"]}, space)


def test_actions_are_checked_against_the_action_space():
    import gymnasium as gym

    space = gym.spaces.Box(-2, 2, (1,), np.float32)
    assert check_actions([0.5], space).shape == (1, 1)
    assert check_actions(np.ones((4, 1)), space).shape == (4, 1)
    for bad, words in [(np.ones(2), "shape (2,)"), (["a"], "dtype <U1"), ([np.nan], "non-finite")]:
        with pytest.raises(ValueError) as e:
            check_actions(bad, space)
        assert words in str(e.value) and "Box(-2.0, 2.0, (1,), float32)" in str(e.value)
    signed = check_actions([[0.3, -0.2, -0.7]], gym.spaces.Box(-1, 1, (3,), np.float32), sign=[2])
    assert signed.tolist() == np.array([[0.3, -0.2, -1.0]], np.float32).tolist()


# Running ---------------------------------------------------------------------------------------


def test_results_do_not_depend_on_the_number_of_envs(tmp_path, policies):
    one = evaluate(PENDULUM, f"{policies}:act", num_envs=1, out=tmp_path / "one", progress=False)
    three = evaluate(PENDULUM, f"{policies}:act", num_envs=3, out=tmp_path / "three", progress=False)
    assert table(one) == table(three)
    assert len({e["return"] for e in one["episodes"]}) == 5  # the seeds make the episodes differ
    assert all(e["length"] == 30 for e in one["episodes"])  # the horizon, settling steps not counted
    chunked = [evaluate(PENDULUM, f"{policies}:chunks", num_envs=n, replan=r, out=tmp_path / f"c{n}{r}", progress=False)
               for n, r in ((1, None), (3, None), (2, 2))]
    assert table(chunked[0]) == table(chunked[1]) != table(chunked[2])
    assert one["summary"]["mean_length"] == 30 and one["summary"]["success_rate"] is None
    files = {p.name for p in (tmp_path / "one").iterdir()}
    assert {"episodes.jsonl", "results.json", "results.csv", "run.json"} <= files


def test_settling_steps_come_before_the_first_observation(tmp_path, policies):
    seen = []

    def policy(observations, tasks):
        seen.extend(np.array(o) for o in observations)
        return np.zeros((len(observations), 1), np.float32)

    bench = {**PENDULUM, "episodes_per_task": 1, "horizon": 1}
    evaluate({**bench, "settle": {"steps": 0}}, policy, out=tmp_path / "a", progress=False)
    evaluate(bench, policy, out=tmp_path / "b", progress=False)
    direct = envhub.make("gym-pendulum")
    first, _ = direct.reset(seed=10)
    for _ in range(3):
        settled, *_ = direct.step(np.array([0.5], np.float32))
    direct.close()
    assert np.array_equal(seen[0], first) and np.array_equal(seen[1], settled)


def test_bad_actions_and_policy_errors_fail_their_episodes(tmp_path):
    class Policy:
        """Episode 0: a wrong shape; 1: raises at its 5th step; 2: good; 3: NaN."""

        def reset(self, slot, episode):
            self.episode, self.step = episode.index, 0

        def __call__(self, observations, tasks):
            self.step += 1
            if self.episode == 0:
                return [np.zeros(3)]
            if self.episode == 1 and self.step == 5:
                raise RuntimeError("model exploded")
            return [np.full(1, np.nan if self.episode == 3 else 0.1, np.float32)]

    bench = {**PENDULUM, "episodes_per_task": 4, "settle": {"steps": 0}}
    results = evaluate(bench, Policy(), out=tmp_path / "bad", progress=False)
    errors = [e["error"] for e in results["episodes"]]
    assert "shape (3,)" in errors[0] and "Box(-2.0, 2.0, (1,), float32)" in errors[0]
    assert "model exploded" in errors[1] and results["episodes"][1]["length"] == 4
    assert errors[2] is None and results["episodes"][2]["length"] == 30
    assert "non-finite" in errors[3]
    assert results["summary"]["errors"] == 3
    with pytest.raises(EvaluationStopped, match="shape"):
        evaluate(bench, Policy(), out=tmp_path / "fast", fail_fast=True, progress=False)
    assert len((tmp_path / "fast" / "episodes.jsonl").read_text().splitlines()) == 1

    def batch(observations, tasks):  # an exception fails every episode of its batch
        raise ValueError("no model")

    both = evaluate(bench, batch, num_envs=2, out=tmp_path / "batch", progress=False)
    assert all("no model" in e["error"] for e in both["episodes"]) and both["summary"]["done"] == 4


def test_a_stopped_evaluation_resumes_without_losing_or_repeating_episodes(tmp_path, policies):
    from envhub.evaluation.callable import load

    act = load(f"{policies}:act")
    bench = {**PENDULUM, "episodes_per_task": 6}
    full = evaluate(bench, act, num_envs=2, out=tmp_path / "full", progress=False)

    class Dies:
        """Raises (as a kill would stop it) once 3 episodes have ended."""

        def __init__(self):
            self.ended = 0

        def __call__(self, observations, tasks):
            if self.ended >= 3:
                raise KeyboardInterrupt
            return act(observations, tasks)

        def end(self, slot, episode, result):
            self.ended += 1

    out = tmp_path / "stopped"
    with pytest.raises(KeyboardInterrupt):
        # Named as `act` is: the same policy for the log's purposes (a resume checks it).
        evaluate(bench, CallablePolicy(Dies(), name=CallablePolicy(act).name), num_envs=1, out=out, progress=False)
    log = (out / "episodes.jsonl").read_text().splitlines()
    assert len(log) == 3
    (out / "episodes.jsonl").write_text("\n".join(log) + '\n{"task": "torn')  # a kill mid-write
    with pytest.raises(FileExistsError):
        evaluate(bench, act, num_envs=2, out=out, progress=False)
    with pytest.raises(ValueError, match="another protocol"):
        evaluate({**bench, "horizon": 31}, act, out=out, resume=True, progress=False)
    resumed = evaluate(bench, act, num_envs=3, out=out, resume=True, progress=False)
    assert table(resumed) == table(full)
    assert resumed["run"]["resumed"] and resumed["summary"]["done"] == 6
    lines = [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines() if x.endswith("}")]
    assert sorted((r["task"], r["index"]) for r in lines) == [("gym-pendulum", k) for k in range(6)]


def test_a_policy_in_another_interpreter_gives_the_same_results(tmp_path, policies):
    from envhub.evaluation import evaluate as ev
    from envhub.evaluation.policy_env import EnvPolicy

    here = ev(PENDULUM, f"{policies}:act", num_envs=2, out=tmp_path / "here", progress=False)
    there = EnvPolicy(f"{policies}:act", [sys.executable], env_name="(this interpreter)")
    remote = ev(PENDULUM, there, num_envs=2, out=tmp_path / "there", progress=False)
    assert table(here) == table(remote)
    assert remote["policy"]["python_env"] == "(this interpreter)"
    assert there.proc.poll() is not None  # closed with the evaluation


ARENA_POLICY = textwrap.dedent(
    """\
    import numpy as np

    def digest(observations, tasks):
        # What it was shown, as numbers: checksums, one value, whether it may write it (as
        # in-process); then it writes into it (as Meta-World's scripted policies do).
        out = []
        for o in observations:
            out.append(np.array([o["cam"].astype(np.float64).sum(), float(o["cam"][1, 2, 0]), o["state"][0],
                                 float(o["cam"].flags.writeable), float(o["cam"].shape[0])]))
            o["cam"].fill(0)
        return out
    """
)


def test_observations_reach_a_policy_in_another_interpreter_through_shared_memory(tmp_path):
    from envhub.evaluation.arena import Arena
    from envhub.evaluation.policy import Episode, Request, Task
    from envhub.evaluation.policy_env import EnvPolicy

    (tmp_path / "arena_policy.py").write_text(ARENA_POLICY)
    there = EnvPolicy(f"{tmp_path / 'arena_policy.py'}:digest", [sys.executable], env_name="(this interpreter)")
    episode = Episode(Task("b", "t", "e", "text", 0), 0)
    rng = np.random.default_rng(3)
    try:
        # 8 KB, then 6 MB (beyond the arena's first MiB: it grows), then small again.
        for side, n in ((16, 3), (512, 8), (8, 2)):
            obs = [
                {"cam": rng.integers(0, 256, (side, side, 3), dtype=np.uint8), "state": rng.normal(size=4)}
                for _ in range(n)
            ]
            answers = there.act([Request(i, episode, 0, o) for i, o in enumerate(obs)])
            for o, a in zip(obs, answers):
                expect = [o["cam"].astype(np.float64).sum(), float(o["cam"][1, 2, 0]), o["state"][0], 1.0, side]
                assert a.tolist() == expect
        assert there.arena.capacity >= 512 * 512 * 3 * 8 > Arena().capacity
    finally:
        there.close()


def test_cli_writes_the_table_and_results(tmp_path, policies):
    from harness import mujoco_or_skip

    mujoco_or_skip(envhub)
    done = run_cli(
        "mujoco", "--tasks", "mujoco-hopper", "--episodes", "2", "--policy", f"{policies}:zeros3",
        "--out", str(tmp_path / "o"), "--num-envs", "2",
    )
    assert done.returncode == 0, done.stderr
    assert "| mujoco-hopper | 2 | 0 |" in done.stdout and "[2/2]" in done.stderr
    results = json.loads((tmp_path / "o" / "results.json").read_text())
    assert [e["init"] for e in results["episodes"]] == [{"seed": 0}, {"seed": 1}]
    assert results["versions"]["envhub"] == envhub.__version__
    bad = run_cli("mujoco", "--tasks", "mujoco-hopper", "--episodes", "1", "--policy", f"{policies}:act",
                  "--out", str(tmp_path / "b"))
    assert bad.returncode == 1 and "| mujoco-hopper | 1 | 1 |" in bad.stdout


def test_tasks_run_side_by_side_with_one_policy_batch(tmp_path):
    """Two tasks with fewer episodes than envs run in sessions at once; one policy call
    serves both tasks' envs; the table is the 1-env table."""
    bench = {
        "name": "two",
        "entries": ["gym-pendulum", "gym-mountain-car-continuous"],
        "episodes_per_task": 3,
        "init": {"seed_start": 0},
        "horizon": 25,
        "success": "none",
    }
    mixed = []
    wait_until = [time.monotonic() + 30]

    def policy(observations, tasks):
        mixed.append(len({t.id for t in tasks}))
        if max(mixed) < 2 and time.monotonic() < wait_until[0]:
            time.sleep(0.05)  # the first task's episodes wait (bounded) for the second's session to start
        return [np.array([np.tanh(o[0] + o[1])], np.float32) for o in observations]

    wide = evaluate(bench, policy, num_envs=6, out=tmp_path / "wide", progress=False)
    assert max(mixed) == 2
    mixed.clear()
    wait_until[0] = 0
    narrow = evaluate(bench, policy, num_envs=1, out=tmp_path / "narrow", progress=False)
    assert max(mixed) == 1
    assert table(wide) == table(narrow)
    assert [t["task"] for t in wide["per_task"]] == ["gym-pendulum", "gym-mountain-car-continuous"]


def test_a_user_registry_file_adds_a_benchmark(tmp_path, policies):
    mine = tmp_path / "mine.yaml"
    mine.write_text(
        textwrap.dedent(
            """\
            environments: []
            benchmarks:
              my-pendulum:
                description: Pendulum by return, 2 episodes
                entries: [gym-pendulum]
                episodes_per_task: 2
                init: {seed_start: 5}
                horizon: 10
                success: none
            """
        )
    )
    registry = ["--registry", "@default", "--registry", str(mine)]
    listed = run_cli(*registry, "--list", "--json")
    assert listed.returncode == 0, listed.stderr
    names = [r["name"] for r in json.loads(listed.stdout)]
    assert "my-pendulum" in names and "libero-spatial" in names
    done = run_cli("my-pendulum", *registry, "--policy", f"{policies}:act", "--out", str(tmp_path / "o"))
    assert done.returncode == 0, done.stderr
    results = json.loads((tmp_path / "o" / "results.json").read_text())
    assert results["protocol"]["source"].startswith(str(mine))
    assert [e["init"] for e in results["episodes"]] == [{"seed": 5}, {"seed": 6}]
