"""`envhub eval --ray ADDRESS --shards N` on a local Ray cluster (`ray start --head`, its own
worker processes): one shard per Ray task, merged to the one-machine table; a Ray worker
killed mid-shard costs only that shard's unfinished episodes, which run again in another
worker. Skipped without Ray (an error under ENVHUB_PY_REQUIRED, where `make` installs it)."""

from __future__ import annotations

import csv
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

import pytest
from harness import import_envhub

import_envhub()

try:
    import ray  # noqa: F401
except ImportError:
    if os.environ.get("ENVHUB_PY_REQUIRED"):
        raise
    pytest.skip("Ray is not installed (requirements-dev.txt has it: make py-install)", allow_module_level=True)

pytestmark = pytest.mark.xdist_group("ray")  # one Ray cluster at a time on a small machine

# Swimmer's episodes run their 1000 steps; a policy call of 2 ms makes a shard last seconds,
# long enough to kill its worker between two episodes.
POLICY = """\
import os
import time
import numpy as np

# The CPUs the process that loads the policy was given (a Ray shard: its --cpus-per-shard).
with open(os.path.join(os.path.dirname(__file__), f"cpus-{os.getpid()}.txt"), "w") as f:
    f.write(os.environ.get("ENVHUB_CPUS", "unset"))

DIMS = {"mujoco-hopper": 3, "mujoco-swimmer": 2}

def act(observations, tasks):
    time.sleep(0.002)
    return [np.tanh(np.asarray(o[: DIMS[t.entry]], dtype=np.float32)) for o, t in zip(observations, tasks)]
"""
RUN = ["mujoco", "--tasks", "mujoco-hopper", "mujoco-swimmer", "--episodes", "3", "--quiet"]
BIN = os.path.join(os.path.dirname(sys.executable), "ray")
# The cluster and its drivers share a token of their own (Ray's token authentication), not
# whatever ~/.ray/auth_token holds: Ray 2.59+ makes one there for local clusters. Ray turns
# 127.0.0.1 into the machine's LAN address (`--node-ip-address` too) unless it runs as a
# single-machine cluster, which RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 asks for on Linux as well:
# the tests' cluster then lives on loopback only.
RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32),
           "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
RAY_LOGS: list[str] = []  # the cluster's log folder, for a failure's message


def cluster_logs() -> str:
    """The end of the cluster's own logs (the GCS and the raylet): why a node died, if it did."""
    out = []
    for folder in RAY_LOGS:
        for name in ("gcs_server.out", "raylet.out", "raylet.err"):
            try:
                with open(os.path.join(folder, "session_latest", "logs", name), errors="replace") as f:
                    out.append(f"--- {name}\n" + "".join(f.readlines()[-25:]))
            except OSError as e:
                out.append(f"--- {name}: {e}")
    return "\n".join(out)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    """A head node on loopback with 3 CPUs: up to 3 shards at once, each in a worker process."""
    port = free_port()
    temp = tempfile.mkdtemp(prefix="ray-", dir="/tmp")  # Ray's socket paths must stay short
    env = {**os.environ, **RAY_ENV}
    start = subprocess.run(
        [BIN, "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=3",
         "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp}",
         "--object-store-memory=100000000", f"--ray-client-server-port={free_port()}"],
        capture_output=True, text=True, timeout=180, env=env,
    )
    assert start.returncode == 0, start.stdout[-2000:] + start.stderr[-2000:]
    RAY_LOGS[:] = [temp]
    try:
        yield f"127.0.0.1:{port}"
    finally:
        RAY_LOGS.clear()
        subprocess.run([BIN, "stop", "--force"], capture_output=True, timeout=120, env=env)
        shutil.rmtree(temp, ignore_errors=True)


def cli(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "envhub.evaluation", *args], capture_output=True, text=True,
                          timeout=900, env={**os.environ, **RAY_ENV}, **kw)


def rows(folder) -> list[dict]:
    with open(os.path.join(folder, "results.csv"), newline="") as f:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(f)]


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    root = tmp_path_factory.mktemp("ray")
    (root / "policy.py").write_text(POLICY)
    done = cli(*RUN, "--policy", f"{root / 'policy.py'}:act", "--out", str(root / "whole"))
    assert done.returncode == 0, done.stderr[-3000:]
    return root


def test_ray_shards_merge_to_the_one_machine_table(cluster, whole, tmp_path):
    out = tmp_path / "run"
    # The policy named relative to the driver's folder: the shards run there (the node has it).
    done = cli(*RUN, "--policy", "policy.py:act", "--ray", cluster, "--shards", "3", "--out", str(out), cwd=whole)
    assert done.returncode == 0, done.stderr[-3000:] + cluster_logs()
    assert rows(out) == rows(whole / "whole")
    merged = json.loads((out / "results.json").read_text())
    assert [s["shard"] for s in merged["run"]["shards"]] == ["0/3", "1/3", "2/3"]
    assert all(s["attempts"] == 1 for s in merged["run"]["shards"])
    # Each shard's workers default to the CPU Ray reserved for it (--cpus-per-shard, 1), not
    # to the node's cores: its evaluation sees ENVHUB_CPUS (the one-machine run saw none).
    given = sorted(p.read_text() for p in whole.glob("cpus-*.txt"))
    assert given.count("1") >= 3 and "unset" in given, given
    # The shards' folders stay, and merge again by hand to the same table.
    again = cli("merge", str(tmp_path / "again"), *(str(out / "shards" / f"shard-{i}") for i in range(3)))
    assert again.returncode == 0 and rows(tmp_path / "again") == rows(whole / "whole")


def wait_for_a_kept_episode(driver: subprocess.Popen, out) -> Any:
    """The driver's log of shard 1, once it holds an episode (the driver still running)."""
    log = out / "shards" / "shard-1" / "episodes.jsonl"
    deadline = time.monotonic() + 300
    while not (log.exists() and log.read_text().count("\n") >= 1):
        assert driver.poll() is None, driver.communicate()[1][-3000:] + cluster_logs()
        assert time.monotonic() < deadline, "shard 1 kept no episode in 300 s"
        time.sleep(0.05)
    return log


def _shard_evaluation(shard: str) -> tuple[int, int] | None:
    """(pid, parent pid) of the evaluation process running `--shard shard`, if one runs."""
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
            with open(f"/proc/{pid}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if b"envhub.evaluation" in argv and shard.encode() in argv:
            return int(pid), ppid
    return None


def test_a_killed_ray_worker_costs_only_its_unfinished_episodes(cluster, whole, tmp_path):
    out = tmp_path / "run"
    driver = subprocess.Popen(
        [sys.executable, "-m", "envhub.evaluation", *RUN, "--policy", f"{whole / 'policy.py'}:act", "--ray", cluster,
         "--shards", "2", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, **RAY_ENV},
    )
    try:
        # Shard 1 is swimmer's three episodes: kill its Ray worker once its first is kept.
        wait_for_a_kept_episode(driver, out)
        found = _shard_evaluation("1/2")
        assert found is not None, "no evaluation process of shard 1/2"
        os.kill(found[1], signal.SIGKILL)  # the Ray worker process that runs the shard's task
        stdout, stderr = driver.communicate(timeout=600)
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
    assert driver.returncode == 0, stderr[-3000:] + cluster_logs()
    assert "shard 1/2 lost" in stderr and "finished ones are kept" in stderr
    assert rows(out) == rows(whole / "whole")
    merged = json.loads((out / "results.json").read_text())
    shard1 = merged["run"]["shards"][1]
    assert shard1["attempts"] == 2
    # The second attempt ran fewer steps than the shard's episodes hold: what was kept did not run again.
    lengths = sum(e["length"] for e in merged["episodes"] if e["task"].endswith("swimmer"))
    assert shard1["env_steps"] < lengths, (shard1, lengths)
    assert _shard_evaluation("1/2") is None  # nothing of the killed attempt is left running


def test_a_killed_driver_resumes_from_what_its_shards_kept(cluster, whole, tmp_path):
    """SIGKILL to the driver mid-run: its shards' tasks end with it (nothing is left running on
    the cluster), and `--resume` goes on from the episodes kept in OUT/shards/."""
    out = tmp_path / "run"
    args = [sys.executable, "-m", "envhub.evaluation", *RUN, "--policy", f"{whole / 'policy.py'}:act", "--ray", cluster,
            "--shards", "2", "--out", str(out)]
    driver = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, **RAY_ENV})
    try:
        log = wait_for_a_kept_episode(driver, out)
        driver.kill()
        driver.wait()
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
    kept = log.read_text().count("\n")
    deadline = time.monotonic() + 120
    while _shard_evaluation("1/2") is not None:  # the cluster ends the dead driver's tasks
        assert time.monotonic() < deadline, "the killed driver's shard still runs after 120 s"
        time.sleep(0.2)
    done = cli(*RUN, "--policy", f"{whole / 'policy.py'}:act", "--ray", cluster, "--shards", "2", "--out", str(out),
               "--resume")
    assert done.returncode == 0, done.stderr[-3000:] + cluster_logs()
    assert rows(out) == rows(whole / "whole")
    merged = json.loads((out / "results.json").read_text())
    assert merged["run"]["resumed"] and kept >= 1
    lengths = sum(e["length"] for e in merged["episodes"] if e["task"].endswith("swimmer"))
    assert merged["run"]["shards"][1]["env_steps"] < lengths
