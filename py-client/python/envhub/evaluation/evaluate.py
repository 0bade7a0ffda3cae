"""`evaluate`: a policy over a benchmark's protocol, results durable episode by episode."""

from __future__ import annotations

import datetime
import os
import platform
import socket
import sys
import tempfile
import time
from importlib import metadata
from typing import Any, Sequence

from .benchmarks import Benchmark, BenchmarkError
from .catalog import Catalog
from .policy import Policy
from .results import EpisodeLog, Progress, markdown, summarize, write_outputs
from .runner import Runner

__all__ = ["evaluate", "resolve", "make_policy"]

# Distributions whose versions the results record where this interpreter has them (a suite
# in its own environment reports through the policy's description or not at all).
PACKAGES = ("gymnasium", "mujoco", "numpy", "metaworld", "robosuite", "hf-libero", "mani-skill", "dm_control", "torch")


def resolve(
    benchmark: str | dict[str, Any],
    tasks: Sequence[str] | None = None,
    episodes: int | None = None,
    registry: Any = None,
) -> tuple[Benchmark, Catalog]:
    """The checked benchmark (a catalog name, or a declaration dict with its `name`),
    narrowed to `tasks` and `episodes`."""
    catalog = Catalog(registry)
    if isinstance(benchmark, dict):
        decl = dict(benchmark)
        bench = catalog.check(str(decl.pop("name", "custom")), decl)
    else:
        bench = catalog.get(benchmark)
    return bench.select(list(tasks) if tasks else None, episodes), catalog


def make_policy(
    policy: Any,
    *,
    policy_env: str | None = None,
    per_task: bool = False,
    server: str | None = None,
    server_protocol: str = "vla-eval",
    registry: Any = None,
) -> Policy:
    """A `Policy` from what the caller gave: a Policy, a callable, `module:function` (run
    here, or in the Python environment `policy_env` of the catalog `registry`), or a server
    URL."""
    from .callable import CallablePolicy, PerTask, load

    if server is not None:
        from .servers import connect

        return connect(server_protocol, server)
    if policy is None:
        raise ValueError("no policy: give --policy module:function or --server URL")
    if policy_env is not None:
        if not isinstance(policy, str):
            raise ValueError("--policy-env runs a policy named `module:function` (an object cannot travel there)")
        from .policy_env import EnvPolicy, env_command

        command = env_command(policy_env, registry)
        return EnvPolicy(policy, command, per_task=per_task, env_name=policy_env)
    if all(hasattr(policy, m) for m in ("act", "start", "end", "describe", "close")):
        return policy
    name = policy if isinstance(policy, str) else None
    target = load(policy) if isinstance(policy, str) else policy
    return CallablePolicy(PerTask(target) if per_task else target, name=name)


def _versions() -> dict[str, Any]:
    from .._envhub import __version__

    packages = {}
    for dist in PACKAGES:
        try:
            packages[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return {"envhub": __version__, "python": platform.python_version(), "packages": packages}


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def evaluate(
    benchmark: str | dict[str, Any],
    policy: Any = None,
    *,
    tasks: Sequence[str] | None = None,
    episodes: int | None = None,
    out: str | os.PathLike[str] | None = None,
    resume: bool = False,
    num_envs: int = 1,
    workers: int | None = None,
    hubs: Any = None,
    registry: Any = None,
    policy_env: str | None = None,
    per_task: bool = False,
    server: str | None = None,
    server_protocol: str = "vla-eval",
    replan: int | None = None,
    fail_fast: bool = False,
    video: bool = False,
    video_failures_only: bool = False,
    video_fps: float = 20.0,
    record: str | os.PathLike[str] | None = None,
    record_fps: int | None = None,
    report: bool = False,
    step_timeout: float | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Runs `policy` over `benchmark` (a catalog name, or a declaration dict) and returns the
    results dict (docs/eval.md); `out` gets `episodes.jsonl` as episodes finish, then
    `results.json`, `results.csv` (and `videos/`, `report.html` when asked); `record`: a
    folder that gets every episode as a LeRobot dataset (docs/eval.md). `policy`:
    `function(observations, tasks) -> actions` (`per_task`: a factory `function(task) ->
    agent`), a `Policy`, or `module:function`; `server`: a policy server's URL instead.
    `resume`: episodes already in `out` are not run again (errored ones are)."""
    if num_envs < 1:
        raise BenchmarkError(f"num_envs must be at least 1, not {num_envs}")
    if replan is not None and replan < 1:
        raise BenchmarkError(f"replan must be at least 1, not {replan}")
    bench, catalog = resolve(benchmark, tasks, episodes, registry)
    folder = os.fspath(out) if out is not None else tempfile.mkdtemp(prefix=f"envhub-eval-{bench.name}-")
    pol = make_policy(
        policy, policy_env=policy_env or (bench.python_env if isinstance(policy, str) and server is None else None),
        per_task=per_task, server=server, server_protocol=server_protocol, registry=catalog.registry,
    )
    try:
        bind = getattr(pol, "bind", None)
        if bind is not None:
            # A policy server takes the benchmark's layout for its protocol (`servers:`),
            # which may ask more of the env (LIBERO's controller pose for vla-eval's states).
            bench = bind(bench)
        description = pol.describe()
        task_plan = [{"id": t.id, "entry": t.entry, "text": t.text, "index": t.index} for t in bench.tasks]
        header = {
            "schema": "envhub.eval/1",
            "benchmark": bench.name,
            "protocol": bench.protocol(),
            "tasks": [t["id"] for t in task_plan],
            "policy": description,
        }
        log = EpisodeLog(folder, header, resume)
        total = len(bench.tasks) * bench.episodes_per_task
        keys = {f"{t.id}#{k}" for t in bench.tasks for k in range(bench.episodes_per_task)}
        skip = log.done() & keys
        meter = Progress(total, len(skip), bench.rule, quiet=not progress)
        videos = None
        if video:
            from .video import EpisodeVideos

            videos = EpisodeVideos(folder, video_failures_only, video_fps)

        dataset = None
        if record is not None:
            from .dataset import EpisodeDataset

            dataset = EpisodeDataset(record, fps=record_fps)

        def log_result(result: dict[str, Any]) -> None:
            log.add(result)
            meter.episode(result.get("success"))

        runner = Runner(
            bench, pol, log_result, num_envs=num_envs, workers=workers, hubs=hubs, registry=catalog.registry,
            step_timeout=step_timeout, fail_fast=fail_fast, replan=replan, videos=videos, dataset=dataset,
        )
        started, t0 = _now(), time.monotonic()
        try:
            runner.run(skip)
        finally:
            meter.close()
            log.close()
            try:
                if videos is not None:
                    videos.close()
            finally:
                if dataset is not None:
                    dataset.close()
        seconds = time.monotonic() - t0
        for t in task_plan:
            if t["id"] in runner.tasks:
                t["text"] = runner.tasks[t["id"]].text
        order = {t["id"]: t["index"] for t in task_plan}
        records = sorted((r for k, r in log.records.items() if k in keys), key=lambda r: (order[r["task"]], r["index"]))
        summary, per_task_rows = summarize(records, task_plan, bench.rule, total)
        ran = len(records) - len(skip)
        summary["episodes_per_minute"] = ran / seconds * 60 if seconds > 0 and ran > 0 else None
        results = {
            "schema": "envhub.eval/1",
            "benchmark": bench.name,
            "description": bench.description,
            "protocol": bench.protocol(),
            "tasks": task_plan,
            "policy": description,
            "versions": _versions(),
            "run": {
                "started": started,
                "finished": _now(),
                "seconds": round(seconds, 3),
                "num_envs": num_envs,
                "workers": workers,
                "hubs": hubs,
                "resumed": bool(resume and skip),
                "host": socket.gethostname(),
                "env_steps": runner.env_steps,
                "out": os.path.abspath(folder),
                "dataset": None if dataset is None else {"path": os.path.abspath(record), **dataset.stats},  # type: ignore[arg-type]
            },
            "summary": summary,
            "per_task": per_task_rows,
            "episodes": records,
        }
        write_outputs(folder, results)
        if report:
            from .report import write_report

            write_report(results, os.path.join(folder, "report.html"))
        return results
    finally:
        pol.close()


def print_table(results: dict[str, Any], stream: Any = None) -> None:
    (stream or sys.stdout).write(markdown(results))
