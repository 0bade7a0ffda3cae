"""`envhub.evaluation`: a policy over a benchmark's own protocol (LIBERO, Meta-World,
robosuite, ManiSkill, dm_control, MuJoCo), episodes in parallel over a session's envs,
results durable episode by episode. `python -m envhub.evaluation --help`; docs/guide/eval.md.

    from envhub.evaluation import evaluate
    results = evaluate("metaworld-mt10", "envhub.evaluation.experts:metaworld",
                       policy_env="metaworld", episodes=3, num_envs=4, out="runs/mt10")
"""

from __future__ import annotations

from .benchmarks import Benchmark, BenchmarkError
from .callable import CallablePolicy, PerTask
from .evaluate import evaluate
from .policy import Episode, Policy, PolicyError, Request, Task
from .runner import EvaluationStopped

__all__ = [
    "Benchmark",
    "BenchmarkError",
    "CallablePolicy",
    "Episode",
    "EvaluationStopped",
    "PerTask",
    "Policy",
    "PolicyError",
    "Request",
    "Task",
    "evaluate",
]
