"""Shards of the suites' benchmarks merge to the one-machine table: Meta-World MT10 with its
scripted experts (in the catalog's `metaworld` environment) and a small LIBERO-spatial run,
each run once on one machine and once as 3 shards (each a separate `evaluate`), then merged.
Skipped where a suite's environment cannot be built (a failure under ENVHUB_SUITES_REQUIRED)."""

from __future__ import annotations

import numpy as np
import pytest
from harness import import_envhub
from libero_env import libero_python
from suite_envs import suite_python

import_envhub()

from envhub.evaluation import evaluate  # noqa: E402
from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.merge import merge  # noqa: E402


def table(results: dict) -> list[tuple]:
    """Every column of the results table but the episode's seconds (a machine's own)."""
    return [(e["task"], e["index"], e["init"], e["success"], e["return"], e["length"], e["error"])
            for e in results["episodes"]]


def sharded(tmp_path, run, n: int = 3) -> tuple[dict, dict]:
    """(one machine's results, the merged results of `n` shards) of `run(out, shard)`."""
    whole = run(tmp_path / "whole", None)
    folders = [tmp_path / f"shard-{i}" for i in range(n)]
    for i, folder in enumerate(folders):
        run(folder, f"{i}/{n}")
    return whole, merge(tmp_path / "merged", folders)


def test_mt10_experts_in_3_shards_merge_to_the_one_machine_table(tmp_path):
    suite_python("metaworld")

    def run(out, shard):
        return evaluate("metaworld-mt10", "envhub.evaluation.experts:metaworld", policy_env="metaworld", episodes=2,
                        num_envs=2, out=out, progress=False, shard=shard)

    whole, merged = sharded(tmp_path, run)
    assert whole["summary"]["errors"] == 0 and len(whole["episodes"]) == 20
    assert table(merged) == table(whole)
    assert merged["per_task"] == whole["per_task"]
    assert {k: v for k, v in merged["summary"].items() if k != "episodes_per_minute"} == \
        {k: v for k, v in whole["summary"].items() if k != "episodes_per_minute"}


def act(observations, tasks):
    # A deterministic function of the observation: the arm pulled toward a point, the gripper open.
    out = []
    for o in observations:
        a = np.zeros(7, np.float32)
        a[:3] = np.tanh(4 * (np.array([0.0, 0.1, 1.0]) - o["robot0_eef_pos"]))
        a[6] = -1.0
        out.append(a)
    return out


# slow: LIBERO's worker starts in four sessions (one machine's and the three shards'), each
# importing robosuite and building a scene per episode (~1 min each on two cores)
@pytest.mark.slow
def test_a_small_libero_run_in_3_shards_merges_to_the_one_machine_table(tmp_path):
    libero_python()
    decl = {**Catalog().declared["libero-spatial"], "name": "libero-spatial", "horizon": 12}

    def run(out, shard):
        return evaluate(decl, act, tasks=["0", "1"], episodes=2, num_envs=2, out=out, progress=False, shard=shard)

    whole, merged = sharded(tmp_path, run)
    assert whole["summary"]["errors"] == 0 and len(whole["episodes"]) == 4
    assert table(merged) == table(whole)
    assert [r["episodes"] for r in merged["run"]["shards"]] == [1, 1, 2]
