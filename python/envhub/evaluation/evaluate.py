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

from .axes import axis_rows
from .benchmarks import Benchmark, BenchmarkError
from .callable import DEFAULT_TIMEOUT
from .catalog import Catalog
from .policy import Policy, PolicyLoadError
from .results import EpisodeLog, FolderLock, Progress, markdown, summarize, write_outputs
from .runner import Runner
from .shards import Shard, episode_keys, parse_shard

__all__ = ["evaluate", "evaluate_seeds", "resolve", "make_policy", "seeds_markdown"]

# Distributions whose versions the results record, as the suite's Python environment (where
# the simulator ran) and this interpreter have them.
PACKAGES = ("gymnasium", "mujoco", "numpy", "metaworld", "robosuite", "hf-libero", "mani-skill", "dm_control", "torch")


def resolve(
    benchmark: str | dict[str, Any] | Benchmark,
    tasks: Sequence[str] | None = None,
    episodes: int | None = None,
    registry: Any = None,
) -> tuple[Benchmark, Catalog]:
    """The checked benchmark (a catalog name, or a declaration dict with its `name`),
    narrowed to `tasks` and `episodes`."""
    catalog = Catalog(registry)
    if isinstance(benchmark, Benchmark):
        return benchmark.select(list(tasks) if tasks else None, episodes), catalog
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
    timeout: float | None = DEFAULT_TIMEOUT,
) -> Policy:
    """A `Policy` from what the caller gave: a Policy, a callable, `module:function` (run
    here, or in the Python environment `policy_env` of the catalog `registry`), or a server
    URL. `timeout`: the seconds each policy call may take (None: unbounded; a `Policy`
    object given whole bounds its own calls). A `module:function` that cannot be loaded
    raises `PolicyLoadError`."""
    from .callable import CallablePolicy, PerTask, load

    if server is not None:
        from .servers import connect

        return connect(server_protocol, server, **({} if timeout is None else {"timeout": timeout}))
    if policy is None:
        raise ValueError("no policy: give --policy module:function or --server URL")
    if policy_env is not None:
        if not isinstance(policy, str):
            raise ValueError("--policy-env runs a policy named `module:function` (an object cannot travel there)")
        from .policy_env import EnvPolicy, env_command

        command = env_command(policy_env, registry)
        return EnvPolicy(policy, command, per_task=per_task, env_name=policy_env, timeout=timeout)
    if all(hasattr(policy, m) for m in ("act", "start", "end", "describe", "close")):
        return policy
    name = policy if isinstance(policy, str) else None
    if isinstance(policy, str):
        try:
            target = load(policy)
        except (ImportError, ValueError, OSError, AttributeError) as e:
            raise PolicyLoadError(f"cannot load the policy `{policy}`: {type(e).__name__}: {e}") from None
    else:
        target = policy
    return CallablePolicy(PerTask(target) if per_task else target, name=name, timeout=timeout)


_VERSIONS_CODE = """
import json, platform
from importlib import metadata
packages = {}
for dist in DISTS:
    try:
        packages[dist] = metadata.version(dist)
    except metadata.PackageNotFoundError:
        pass
print(json.dumps({"python": platform.python_version(), "packages": packages}))
"""


def _here() -> dict[str, Any]:
    packages = {}
    for dist in PACKAGES:
        try:
            packages[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return {"python": platform.python_version(), "packages": packages}


def _python_env_of(registry: Any, entry: str) -> str | None:
    inner = getattr(registry, "_inner", None)
    ask = getattr(inner, "python_env_of", None)
    return ask(entry) if ask is not None else None


def _in_env(name: str, registry: Any) -> dict[str, Any]:
    """The Python and package versions of the catalog's Python environment `name`, asked of
    its interpreter (the one the workers ran in)."""
    import json
    import subprocess

    from .policy_env import env_command

    code = _VERSIONS_CODE.replace("DISTS", repr(PACKAGES))
    try:
        done = subprocess.run(
            [*env_command(name, registry), "-c", code], capture_output=True, text=True, timeout=300
        )
        if done.returncode == 0:
            return json.loads(done.stdout.strip().splitlines()[-1])
        error = (done.stderr or done.stdout).strip()[-500:]
    except (OSError, subprocess.TimeoutExpired, ValueError, IndexError) as e:
        error = f"{type(e).__name__}: {e}"
    return {"error": f"cannot ask the Python environment `{name}` for its versions: {error}"}


def _versions(bench: Benchmark, registry: Any) -> dict[str, Any]:
    """The versions of what ran the simulator (`python`, `packages`: the suite's Python
    environment where its entries run in one, else this interpreter), the environment's
    name, and this interpreter's (`hub`)."""
    from .._envhub import __version__

    here = _here()
    envs = sorted({e for e in (_python_env_of(registry, t.entry) for t in bench.tasks) if e is not None})
    out: dict[str, Any] = {"envhub": __version__, "python_env": envs[0] if envs else None}
    suite = _in_env(envs[0], registry) if envs else here
    out.update(suite)
    if len(envs) > 1:
        out["other_python_envs"] = {name: _in_env(name, registry) for name in envs[1:]}
    out["hub"] = here
    return out


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def evaluate(
    benchmark: str | dict[str, Any] | Benchmark,
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
    policy_timeout: float | None = DEFAULT_TIMEOUT,
    progress: bool = True,
    shard: Any = None,
    on_episode: Any = None,
) -> dict[str, Any]:
    """Runs `policy` over `benchmark` (a catalog name, or a declaration dict) and returns the
    results dict (docs/guide/eval.md); `out` gets `episodes.jsonl` as episodes finish, then
    `results.json`, `results.csv` (and `videos/`, `report.html` when asked); `record`: a
    folder that gets every episode as a LeRobot dataset (docs/guide/eval.md). `policy`:
    `function(observations, tasks) -> actions` (`per_task`: a factory `function(task) ->
    agent`), a `Policy`, or `module:function`; `server`: a policy server's URL instead.
    `resume`: episodes already in `out` are not run again (errored ones are).
    `policy_timeout`: seconds each policy call may take before its batch's episodes fail
    (None: unbounded). `shard`: a `Shard` (or `"I/N"`): only its slice of the episodes runs
    (`envhub eval merge` joins the shards' folders). `on_episode`: called with each episode's
    record once it is durable."""
    if num_envs < 1:
        raise BenchmarkError(f"num_envs must be at least 1, not {num_envs}")
    if replan is not None and replan < 1:
        raise BenchmarkError(f"replan must be at least 1, not {replan}")
    bench, catalog = resolve(benchmark, tasks, episodes, registry)
    if isinstance(shard, str):
        shard = parse_shard(shard)
    folder = os.fspath(out) if out is not None else tempfile.mkdtemp(prefix=f"envhub-eval-{bench.name}-")
    lock = FolderLock(folder)  # before anything starts: a second run into the folder is refused
    try:
        return _evaluate(
            bench, catalog, folder, policy, resume=resume, num_envs=num_envs, workers=workers, hubs=hubs,
            policy_env=policy_env, per_task=per_task, server=server, server_protocol=server_protocol,
            replan=replan, fail_fast=fail_fast, video=video, video_failures_only=video_failures_only,
            video_fps=video_fps, record=record, record_fps=record_fps, report=report,
            step_timeout=step_timeout, policy_timeout=policy_timeout, progress=progress, shard=shard,
            on_episode=on_episode,
        )
    finally:
        lock.release()


def _evaluate(
    bench: Benchmark,
    catalog: Catalog,
    folder: str,
    policy: Any,
    *,
    resume: bool,
    num_envs: int,
    workers: int | None,
    hubs: Any,
    policy_env: str | None,
    per_task: bool,
    server: str | None,
    server_protocol: str,
    replan: int | None,
    fail_fast: bool,
    video: bool,
    video_failures_only: bool,
    video_fps: float,
    record: Any,
    record_fps: int | None,
    report: bool,
    step_timeout: float | None,
    policy_timeout: float | None,
    progress: bool,
    shard: Shard | None,
    on_episode: Any,
) -> dict[str, Any]:
    pol = make_policy(
        policy, policy_env=policy_env or (bench.python_env if isinstance(policy, str) and server is None else None),
        per_task=per_task, server=server, server_protocol=server_protocol, registry=catalog.registry,
        timeout=policy_timeout,
    )
    try:
        bind = getattr(pol, "bind", None)
        if bind is not None:
            # A policy server takes the benchmark's layout for its protocol (`servers:`),
            # which may ask more of the env (LIBERO's controller pose for vla-eval's states).
            from .servers.layout import LayoutError

            try:
                bench = bind(bench)
            except LayoutError as e:  # what the server asks for, refused: a usage error
                raise BenchmarkError(str(e)) from None
        description = pol.describe()
        task_plan = [{"id": t.id, "entry": t.entry, "text": t.text, "index": t.index, **({"axis": t.axis} if t.axis else {})} for t in bench.tasks]
        header = {
            "schema": "envhub.eval/1",
            "benchmark": bench.name,
            "protocol": bench.protocol(),
            "tasks": [t["id"] for t in task_plan],
            "policy": description,
        }
        if shard is not None:
            header["shard"] = shard.as_dict()
        log = EpisodeLog(folder, header, resume)
        mine = episode_keys(bench) if shard is None else shard.keys(bench)
        total, keys = len(mine), set(mine)
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
            if on_episode is not None:
                on_episode(result)
            if result.get("error") is not None:
                meter.error(f"{result['task']}#{result['index']}", str(result["error"]))
            meter.episode(result.get("success"))

        runner = Runner(
            bench, pol, log_result, num_envs=num_envs, workers=workers, hubs=hubs, registry=catalog.registry,
            step_timeout=step_timeout, fail_fast=fail_fast, replan=replan, videos=videos, dataset=dataset,
        )
        started, t0 = _now(), time.monotonic()
        try:
            runner.run(skip | (set(episode_keys(bench)) - keys))  # another shard's episodes are skipped
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
            "versions": _versions(bench, catalog.registry),
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
            **axis_rows(task_plan, records, bench.rule),
            "episodes": records,
        }
        if shard is not None:
            results["shard"] = shard.as_dict()
        write_outputs(folder, results, report)
        return results
    finally:
        pol.close()


def evaluate_seeds(
    benchmark: str | dict[str, Any] | Benchmark,
    policy: Any = None,
    *,
    seeds: int,
    out: str | os.PathLike[str],
    tasks: Sequence[str] | None = None,
    episodes: int | None = None,
    registry: Any = None,
    **options: Any,
) -> dict[str, Any]:
    """`evaluate` under the protocol's first `seeds` seeds (`Benchmark.reseeded`: seed 0 is
    the protocol itself), each run in `out/seed-<s>`; returns (and writes to
    `out/seeds.json`) each seed's success rate and their spread, overall and per task."""
    from .results import _write_json
    from .stats import spread

    if seeds < 1:
        raise BenchmarkError(f"--seeds must be at least 1, not {seeds}")
    bench, catalog = resolve(benchmark, tasks, episodes, registry)
    variants = [bench.reseeded(s) for s in range(seeds)]  # a protocol with no seed to vary fails here
    folder = os.fspath(out)
    lock = FolderLock(folder)
    try:
        runs = [
            evaluate(b, policy, out=os.path.join(folder, f"seed-{s}"), registry=catalog.registry, **options)
            for s, b in enumerate(variants)
        ]
    finally:
        lock.release()
    rule = bench.rule
    per_task = []
    for i, t in enumerate(runs[0]["per_task"]):
        rates = [r["per_task"][i]["success_rate"] for r in runs]
        per_task.append({"task": t["task"], "rates": rates, **spread(rates)})
    rates = [r["summary"]["success_rate"] for r in runs]
    summary = {
        "schema": "envhub.eval.seeds/1",
        "benchmark": bench.name,
        "rule": rule,
        "seeds": [
            {"seed": s, "init": b.init, "out": r["run"]["out"], "success_rate": r["summary"]["success_rate"],
             "ci95": r["summary"].get("ci95"), "errors": r["summary"]["errors"], "mean_return": r["summary"]["mean_return"]}
            for s, (b, r) in enumerate(zip(variants, runs))
        ],
        "spread": spread(rates),
        "return_spread": spread([r["summary"]["mean_return"] for r in runs]),
        "per_task": per_task,
        "policy": runs[0]["policy"],
    }
    _write_json(os.path.join(folder, "seeds.json"), summary)
    return summary


def seeds_markdown(summary: dict[str, Any]) -> str:
    """The per-seed success rates and their spread, per task and overall."""
    n = len(summary["seeds"])

    def pct(x: Any) -> str:
        return "–" if x is None else f"{100 * x:.1f}"

    head = " | ".join(f"seed {s}" for s in range(n))
    lines = [
        f"### {summary['benchmark']}: {summary['policy'].get('name', summary['policy'].get('kind', ''))}, {n} seeds",
        "",
        f"| task | {head} | mean | std | min–max |",
        "|---|" + "---:|" * (n + 3),
    ]
    overall = {"task": "**all**", "rates": [s["success_rate"] for s in summary["seeds"]], **summary["spread"]}
    for row in summary["per_task"] + [overall]:
        cells = " | ".join(pct(r) for r in row["rates"])
        span = "–" if row["min"] is None else f"{pct(row['min'])}–{pct(row['max'])}"
        lines.append(f"| {row['task']} | {cells} | {pct(row['mean'])} | {pct(row['std'])} | {span} |")
    lines += ["", "Success rates in percent; std: the sample standard deviation over the seeds."]
    return "\n".join(lines) + "\n"


def print_table(results: dict[str, Any], stream: Any = None) -> None:
    (stream or sys.stdout).write(markdown(results))
