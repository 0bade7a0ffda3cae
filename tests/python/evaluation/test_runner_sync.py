"""The evaluation's synchronous runner (`ENVHUB_EVAL_READY_ENVS=0`, for benchmarks) against
its ready-env runner: every round waits for every env out instead of taking the first
workers' answers, and ended envs reset together instead of alone (`send_reset`) as their
worker comes back; the results table is the same (4 envs over 2 workers, Pendulum).
"""

from __future__ import annotations

from eval_policies import policies, table  # noqa: F401 - policies is a fixture
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import evaluate  # noqa: E402
from envhub.evaluation.runner import Runner  # noqa: E402

PENDULUM = {
    "name": "pendulum",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 6,
    "init": {"seed_start": 10},
    "horizon": 30,
    "settle": {"steps": 3, "action": [0.5]},
    "success": "none",
}


def test_the_synchronous_runner_gives_the_ready_env_runners_results(tmp_path, policies, monkeypatch):
    calls: list[bool] = []
    recv = Runner._recv

    def spy(self, s, all_back):
        calls.append(all_back)
        return recv(self, s, all_back)

    monkeypatch.setattr(Runner, "_recv", spy)
    resets: list[list[int]] = []
    send_reset = envhub.VectorEnv.send_reset

    def spy_reset(self, env_ids, **kw):
        resets.append(list(env_ids))
        return send_reset(self, env_ids, **kw)

    monkeypatch.setattr(envhub.VectorEnv, "send_reset", spy_reset)
    runs = {}
    for mode in ("1", "0"):
        monkeypatch.setenv("ENVHUB_EVAL_READY_ENVS", mode)
        calls.clear()
        resets.clear()
        runs[mode] = evaluate(
            PENDULUM, f"{policies}:act", num_envs=4, workers=2, out=tmp_path / mode, progress=False
        )
        if mode == "0":
            assert calls and all(calls)  # every round waited for every env out
            assert not resets  # ended envs reset together
        else:
            assert not all(calls)  # rounds took the first workers' answers
            # The 2 episodes after the first 4: their envs were reset alone (`send_reset`).
            reset_envs = [e for ids in resets for e in ids]
            assert len(reset_envs) == len(set(reset_envs)) == 2, resets
    assert table(runs["1"]) == table(runs["0"])
    assert len({e["return"] for e in runs["0"]["episodes"]}) == 6  # the seeds make the episodes differ
    assert all(e["error"] is None and e["length"] == 30 for e in runs["0"]["episodes"])
