"""`python -m envhub.evaluation` (and `envhub eval`, which runs it): exit status 0 when every
episode ran, 1 when an episode or the run failed, 2 for a usage error (an unknown
benchmark, task or option; nothing started)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from ..wire.errors import RegistryError
from .benchmarks import BenchmarkError
from .results import ResumeError


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="envhub eval",
        description="Run a policy over a benchmark of the catalog with the benchmark's own protocol.",
    )
    p.add_argument("benchmark", nargs="?", help="a benchmark of the catalog (--list shows them)")
    p.add_argument("--list", action="store_true", help="list the catalog's benchmarks and exit")
    p.add_argument("--json", action="store_true", help="with --list: as JSON")
    p.add_argument("--registry", action="append", help="registry file (repeatable; @default is the built-in one)")
    p.add_argument("--tasks", nargs="+", help="task ids (or their last part: 0, reach-v3) to run")
    p.add_argument("--episodes", type=int, help="episodes per task (default: the benchmark's)")
    p.add_argument("--policy", help="module:function or path/file.py:function (a batched callable)")
    p.add_argument("--per-task", action="store_true", help="--policy names a factory function(task) -> agent")
    p.add_argument("--policy-env", help="run --policy in this catalog Python environment (its own interpreter)")
    p.add_argument("--server", help="a policy server's URL (ws://host:port)")
    p.add_argument("--server-protocol", choices=["vla-eval", "openpi", "lerobot"], default="vla-eval")
    p.add_argument("--replan", type=int, help="use only the first K actions of each chunk")
    p.add_argument("--out", help="output folder (episodes.jsonl, results.json, results.csv)")
    p.add_argument("--resume", action="store_true", help="go on with the evaluation in --out")
    p.add_argument("--num-envs", type=int, default=1, help="envs (episodes in parallel)")
    p.add_argument("--workers", type=int, help="worker processes per session (default: its share of the cores)")
    p.add_argument("--hubs", help="place envs on other hubs: all, or names separated by commas")
    p.add_argument("--step-timeout", type=float, help="seconds a step may take before its episode fails")
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed episode")
    p.add_argument("--video", action="store_true", help="one MP4 per episode in --out/videos")
    p.add_argument("--video-failures-only", action="store_true", help="with --video: only failed episodes")
    p.add_argument("--video-fps", type=float, default=20.0)
    p.add_argument("--report", action="store_true", help="write --out/report.html")
    p.add_argument("--record", metavar="DIR", help="record every episode as a LeRobot v3 dataset in DIR (appended to)")
    p.add_argument("--record-fps", type=int, help="the dataset's fps (default: the env's render_fps)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def list_benchmarks(registry: Any, as_json: bool) -> int:
    from .catalog import Catalog

    catalog = Catalog(registry)
    rows = []
    for name in catalog.names():
        b = catalog.get(name)
        rows.append(
            {
                "name": name,
                "tasks": len(b.tasks),
                "episodes_per_task": b.episodes_per_task,
                "horizon": b.horizon,
                "success": b.rule,
                "description": b.description,
            }
        )
    if as_json:
        print(json.dumps(rows, indent=1))
        return 0
    width = max((len(r["name"]) for r in rows), default=4)
    print(f"{'NAME':<{width}}  TASKS  EPISODES  HORIZON  SUCCESS    DESCRIPTION")
    for r in rows:
        print(
            f"{r['name']:<{width}}  {r['tasks']:>5}  {r['episodes_per_task']:>8}  {r['horizon']:>7}  "
            f"{r['success']:<9}  {r['description']}"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    registry = args.registry
    try:
        if args.list:
            return list_benchmarks(registry, args.json)
        if not args.benchmark:
            print("envhub eval: error: name a benchmark (--list shows them)", file=sys.stderr)
            return 2
        if args.policy is None and args.server is None:
            print("envhub eval: error: give --policy module:function or --server URL", file=sys.stderr)
            return 2
        from .evaluate import evaluate, resolve

        resolve(args.benchmark, args.tasks, args.episodes, registry)  # usage errors before anything starts
        hubs = args.hubs if args.hubs in (None, "all", "local") else args.hubs.split(",")
        results = evaluate(
            args.benchmark,
            args.policy,
            tasks=args.tasks,
            episodes=args.episodes,
            out=args.out,
            resume=args.resume,
            num_envs=args.num_envs,
            workers=args.workers,
            hubs=hubs,
            registry=registry,
            policy_env=args.policy_env,
            per_task=args.per_task,
            server=args.server,
            server_protocol=args.server_protocol,
            replan=args.replan,
            fail_fast=args.fail_fast,
            video=args.video,
            video_failures_only=args.video_failures_only,
            video_fps=args.video_fps,
            record=args.record,
            record_fps=args.record_fps,
            report=args.report,
            step_timeout=args.step_timeout,
            progress=not args.quiet,
        )
    except (BenchmarkError, FileExistsError, ResumeError, RegistryError) as e:
        print(f"envhub eval: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("envhub eval: interrupted; --resume goes on from the last finished episode", file=sys.stderr)
        return 130
    except Exception as e:
        from .runner import EvaluationStopped

        kind = "stopped" if isinstance(e, EvaluationStopped) else f"error: {type(e).__name__}"
        print(f"envhub eval: {kind}: {e}", file=sys.stderr)
        return 1
    from .results import markdown

    sys.stdout.write(markdown(results))
    print(f"\nresults: {results['run']['out']}/results.json", file=sys.stderr)
    return 1 if results["summary"]["errors"] else 0
