"""`envhub eval --shard I/N` and `envhub eval merge`: shards of an evaluation, each a fixed
slice of its episodes, merge into the table one machine writes, row for row; a merge that
could not give that table is refused, naming the folder and why. The MuJoCo benchmark runs
natively (no suite environment), with a deterministic policy."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys

import pytest
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation.benchmarks import Benchmark  # noqa: E402
from envhub.evaluation.distribute import shard_argv  # noqa: E402
from envhub.evaluation.results import FolderLock  # noqa: E402
from envhub.evaluation.shards import Shard, ShardError, episode_keys, parse_shard  # noqa: E402

POLICY = """\
import numpy as np

DIMS = {"mujoco-hopper": 3, "mujoco-swimmer": 2}

def act(observations, tasks):
    # A deterministic function of the observation alone, the action's size from the task.
    return [np.tanh(np.asarray(o[: DIMS[t.entry]], dtype=np.float32)) for o, t in zip(observations, tasks)]

def other(observations, tasks):
    return [np.zeros(DIMS[t.entry], np.float32) for t in tasks]
"""

RUN = ["mujoco", "--tasks", "mujoco-hopper", "mujoco-swimmer", "--episodes", "3"]


def cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "envhub.evaluation", *args], capture_output=True, text=True, timeout=600, cwd=cwd
    )


def rows(folder) -> list[dict]:
    """results.csv's rows less the time each episode took (the one column a machine changes)."""
    with open(os.path.join(folder, "results.csv"), newline="") as f:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(f)]


def tasks_csv(folder) -> str:
    with open(os.path.join(folder, "tasks.csv")) as f:
        return f.read()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One machine's run and the same run as 3 shards (each its own process), with the policy file."""
    root = tmp_path_factory.mktemp("shards")
    (root / "policy.py").write_text(POLICY)
    policy = f"{root / 'policy.py'}:act"
    whole = cli(*RUN, "--policy", policy, "--out", str(root / "whole"), "--quiet")
    assert whole.returncode == 0, whole.stderr[-3000:]
    for i in range(3):
        done = cli(*RUN, "--policy", policy, "--shard", f"{i}/3", "--out", str(root / f"s{i}"), "--quiet")
        assert done.returncode == 0, done.stderr[-3000:]
    return root, policy


def test_shards_partition_the_episodes_the_same_way_every_time():
    from envhub.evaluation.benchmarks import TaskSpec

    for tasks, episodes in ((1, 1), (2, 3), (10, 50), (3, 7)):
        bench = Benchmark.__new__(Benchmark)
        bench.tasks = [TaskSpec(f"b/t{i}", "e", {}, "", i) for i in range(tasks)]
        bench.episodes_per_task = episodes
        every = episode_keys(bench)
        for n in (1, 2, 3, 4, 7, 64):
            slices = [Shard(i, n).keys(bench) for i in range(n)]
            assert [k for s in slices for k in s] == every  # contiguous, in order, each once
            assert max(map(len, slices)) - min(map(len, slices)) <= 1
            assert slices == [Shard(i, n).keys(bench) for i in range(n)]


@pytest.mark.parametrize("text", ["3/3", "-1/3", "1", "a/b", "0/0", "1/2/3", ""])
def test_a_bad_shard_is_refused_naming_the_valid_form(text):
    with pytest.raises(ShardError, match="I/N|0 to N-1"):
        parse_shard(text)


def test_the_shards_command_line_leaves_out_how_it_is_distributed():
    argv = ["mujoco", "--ray", "--shards", "3", "--out", "o", "--policy", "p:f", "--report", "--ray", "h:1",
            "--resume", "--slurm-script=x.sh", "--episodes", "2", "--quiet", "--cpus-per-shard", "2"]
    assert shard_argv(argv) == ["mujoco", "--policy", "p:f", "--episodes", "2"]


def test_three_shards_merge_to_the_one_machine_table(runs):
    root, _ = runs
    done = cli("merge", str(root / "merged"), *(str(root / f"s{i}") for i in range(3)), "--report")
    assert done.returncode == 0, done.stderr
    assert rows(root / "merged") == rows(root / "whole")
    assert tasks_csv(root / "merged") == tasks_csv(root / "whole")
    whole = json.loads((root / "whole" / "results.json").read_text())
    merged = json.loads((root / "merged" / "results.json").read_text())
    for key in ("benchmark", "protocol", "tasks", "policy", "per_task"):
        assert whole[key] == merged[key], key
    assert {**whole["summary"], "episodes_per_minute": 0} == {**merged["summary"], "episodes_per_minute": 0}
    # The table printed is the one machine's table; the report and results name every shard's time.
    assert done.stdout == cli("merge", str(root / "merged"), *(str(root / f"s{i}") for i in range(3))).stdout
    shards = merged["run"]["shards"]
    assert [s["shard"] for s in shards] == ["0/3", "1/3", "2/3"] and sum(s["episodes"] for s in shards) == 6
    assert all(s["seconds"] is not None and s["host"] for s in shards)
    assert "| shard | host | episodes |" in done.stderr and "| 2/3 |" in done.stderr
    page = (root / "merged" / "report.html").read_text()
    assert '<table id="shards"' in page and '>2/3</td>' in page


def test_a_shard_runs_its_slice_only_and_resumes_within_it(runs):
    root, policy = runs
    s1 = json.loads((root / "s1" / "results.json").read_text())
    assert s1["shard"] == {"index": 1, "count": 3}
    # 6 episodes in the benchmark's order, cut in 3: shard 1 is the third and the fourth.
    assert [(e["task"], e["index"]) for e in s1["episodes"]] == [("mujoco-hopper", 2), ("mujoco-swimmer", 0)]
    again = cli(*RUN, "--policy", policy, "--shard", "1/3", "--out", str(root / "s1"), "--resume", "--quiet")
    assert again.returncode == 0 and json.loads((root / "s1" / "results.json").read_text())["summary"]["done"] == 2
    other = cli(*RUN, "--policy", policy, "--shard", "2/3", "--out", str(root / "s1"), "--resume", "--quiet")
    assert other.returncode == 2 and "differs in shard" in other.stderr


def copy_shards(root, dest) -> list[str]:
    out = []
    for i in range(3):
        shutil.copytree(root / f"s{i}", dest / f"s{i}")
        out.append(str(dest / f"s{i}"))
    return out


def test_a_merge_that_could_not_give_the_one_machine_table_is_refused(runs, tmp_path):
    root, policy = runs
    s = copy_shards(root, tmp_path)

    def refused(*folders, match):
        done = cli("merge", str(tmp_path / "m"), *folders)
        assert done.returncode == 2, done.stdout + done.stderr
        assert match in done.stderr, done.stderr
        assert "Traceback" not in done.stderr
        assert not (tmp_path / "m" / "results.json").exists()

    refused(s[0], s[1], match="shards 2/3 are missing")
    refused(s[0], s[1], s[1], s[2], match="shard 1/3 is given twice")
    refused(s[0], s[1], s[2], str(tmp_path / "nowhere"), match="does not exist")
    refused(s[0], s[1], str(root / "whole"), match="run without --shard")
    # Shards of another split, another policy, other versions.
    two = cli(*RUN, "--policy", policy, "--shard", "1/2", "--out", str(tmp_path / "half"), "--quiet")
    assert two.returncode == 0, two.stderr
    refused(s[0], s[1], s[2], str(tmp_path / "half"), match="different ways")
    zero = cli(*RUN, "--policy", policy.replace(":act", ":other"), "--shard", "2/3", "--out", str(tmp_path / "o"), "--quiet")
    assert zero.returncode == 0, zero.stderr
    refused(s[0], s[1], str(tmp_path / "o"), match="differ in policy")
    res = json.loads((tmp_path / "s2" / "results.json").read_text())
    res["versions"]["envhub"] = "0.0.0-other"
    (tmp_path / "s2" / "results.json").write_text(json.dumps(res))
    refused(*s, match="other versions")
    shutil.rmtree(tmp_path / "s2")
    shutil.copytree(root / "s2", tmp_path / "s2")
    # A shard still being written (its folder's lock held), and one that did not finish.
    lock = FolderLock(s[2])
    try:
        refused(*s, match="still being written")
    finally:
        lock.release()
    (tmp_path / "s2" / "results.json").unlink()
    refused(*s, match="did not finish")
    # The merged folder is not a shard, nor a folder holding an evaluation; an earlier merge's is replaced.
    shutil.rmtree(tmp_path / "s2")
    shutil.copytree(root / "s2", tmp_path / "s2")
    done = cli("merge", s[0], *s)
    assert done.returncode == 2 and "is one of the shards" in done.stderr
    shutil.copytree(root / "whole", tmp_path / "whole")
    done = cli("merge", str(tmp_path / "whole"), *s)
    assert done.returncode == 2 and "already holds an evaluation" in done.stderr
    for _ in range(2):
        done = cli("merge", str(tmp_path / "m"), *s)
        assert done.returncode == 0, done.stderr


def test_slurm_script_run_by_hand_gives_the_one_machine_table(runs, tmp_path):
    """No Slurm here: the script is run as each array task would run it (SLURM_ARRAY_TASK_ID
    0..N-1), with an `sbatch` on PATH that records the merge job task 0 submits; then the
    merge job's command, by hand."""
    root, policy = runs
    script = tmp_path / "eval.sbatch"
    out = tmp_path / "run"
    done = cli(*RUN, "--policy", policy, "--shards", "3", "--out", str(out), "--slurm-script", str(script), "--report")
    assert done.returncode == 0, done.stderr
    text = script.read_text()
    assert "#SBATCH --array=0-2" in text and "--shard \"$I/3\"" in text and "--resume" in text
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "sbatch").write_text('#!/bin/sh\nfor a in "$@"; do printf "%s\\n" "$a"; done > "$SBATCH_ARGS"\n')
    (bin_dir / "sbatch").chmod(0o755)
    envhub_bin = bin_dir / "envhub"
    envhub_bin.write_text(f'#!/bin/sh\n[ "$1" = eval ] && shift\nexec {sys.executable} -m envhub.evaluation "$@"\n')
    envhub_bin.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "SBATCH_ARGS": str(tmp_path / "sbatch.args"),
           "SLURM_ARRAY_JOB_ID": "4242"}
    for i in range(3):
        if i == 1:  # one shard finished, two not started
            status = json.loads(cli("status", str(out), "--json").stdout)
            assert (status["done"], status["total"], status["finished"]) == (2, 6, False), status
            assert "1 finished, 2 not started" in cli("status", str(out)).stdout
        task = subprocess.run(["bash", str(script)], env={**env, "SLURM_ARRAY_TASK_ID": str(i)},
                              capture_output=True, text=True, timeout=600)
        assert task.returncode == 0, task.stderr[-3000:]
    submitted = (tmp_path / "sbatch.args").read_text().splitlines()
    assert "--dependency=afterany:4242" in submitted
    wrap = submitted[submitted.index("--wrap") + 1]
    # The run's progress from the shards' folders: every episode done, every shard finished.
    status = cli("status", str(out))
    assert status.returncode == 0 and status.stdout.startswith("[6/6] | ") and "3 shards: 3 finished" in status.stdout
    merged = subprocess.run(["sh", "-c", wrap], env=env, capture_output=True, text=True, timeout=300)
    assert merged.returncode == 0, merged.stderr
    assert rows(out) == rows(root / "whole") and tasks_csv(out) == tasks_csv(root / "whole")
    assert (out / "report.html").exists()


def test_shard_options_that_do_not_fit_are_usage_errors(runs, tmp_path):
    _, policy = runs
    for args, match in (
        (["--shard", "3/3"], "0 to N-1"),
        (["--shards", "3"], "--shards N goes with --ray or --slurm-script"),
        (["--shard", "0/2", "--seeds", "2"], "not with --seeds"),
        (["--slurm-script", str(tmp_path / "x")], "need --shards N"),
        (["--slurm-script", str(tmp_path / "x"), "--shards", "2", "--slurm-option", "partition=gpu"], "--slurm-option"),
    ):
        done = cli(*RUN, "--policy", policy, "--out", str(tmp_path / "o"), *args)
        assert done.returncode == 2 and match in done.stderr, (args, done.stderr)


@pytest.mark.parametrize("cpus", [-1.0, float("nan")])
def test_a_bad_cpus_per_shard_is_refused_before_ray_is_asked(cpus, tmp_path):
    from envhub.evaluation.ray_shards import run_on_ray

    with pytest.raises(ShardError, match="--cpus-per-shard must be 0 or more"):
        run_on_ray(["mujoco"], str(tmp_path / "o"), 2, bench=None, cpus_per_shard=cpus)
