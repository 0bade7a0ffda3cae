"""`python -m envhub.evaluation` (and `envhub eval`, which execs it): exit status 0 when every
episode ran, 1 when an episode or the run failed, 2 for a usage error (an unknown
benchmark, task, option or policy; a folder in use; nothing started), 128 + the signal's
number when stopped by SIGINT (130), SIGTERM (143) or SIGHUP (129): the envs, their
workers and the policy's process are down when it exits."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from typing import Any

from ..wire.errors import RegistryError
from .benchmarks import BenchmarkError
from .callable import DEFAULT_TIMEOUT
from .policy import PolicyLoadError
from .results import ResumeError


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"`{text}` is not a number of seconds") from None
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"`{text}`: give a number of seconds, 0 or more (0: no deadline)")
    return value


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="envhub eval",
        description="Run a policy over a benchmark of the catalog with the benchmark's own protocol. "
        "`envhub eval compare RUN_A RUN_B` compares two runs, `envhub eval merge OUT SHARD...` joins the shards "
        "of a run, `envhub eval status OUT` shows a sharded run's progress (--help there).",
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
    p.add_argument("--out", help="output folder (episodes.jsonl, results.json, results.csv); required")
    p.add_argument("--resume", action="store_true", help="go on with the evaluation in --out")
    p.add_argument(
        "--seeds",
        type=int,
        metavar="N",
        help="run the protocol under its first N seeds (--out/seed-0 is the protocol itself) and report the spread",
    )
    p.add_argument("--num-envs", type=int, default=1, help="envs (episodes in parallel)")
    p.add_argument("--workers", type=int, help="worker processes per session (default: its share of the cores)")
    p.add_argument("--hubs", help="place envs on other hubs: all, or names separated by commas")
    p.add_argument("--step-timeout", type=float, help="seconds a step may take before its episode fails")
    p.add_argument(
        "--policy-timeout",
        type=_seconds,
        default=DEFAULT_TIMEOUT,
        metavar="SECONDS",
        help=f"seconds a policy call (in-process, --policy-env, --server) may take before its batch's episodes "
        f"fail (default {DEFAULT_TIMEOUT:g}; 0: no deadline)",
    )
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed episode")
    p.add_argument("--video", action="store_true", help="one MP4 per episode in --out/videos")
    p.add_argument("--video-failures-only", action="store_true", help="with --video: only failed episodes")
    p.add_argument("--video-fps", type=float, default=20.0)
    p.add_argument("--report", action="store_true", help="write --out/report.html")
    p.add_argument("--record", metavar="DIR", help="record every episode as a LeRobot v3 dataset in DIR (appended to)")
    p.add_argument("--record-fps", type=int, help="the dataset's fps (default: the env's render_fps)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    g = p.add_argument_group("more than one machine (docs/guide/eval.md)")
    g.add_argument("--shard", metavar="I/N", help="run only shard I (0 to N-1) of N: a fixed slice of the episodes")
    g.add_argument("--shards", type=int, metavar="N", help="with --ray or --slurm-script: the number of shards")
    g.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run the shards as Ray tasks (the cluster at ADDRESS, RAY_ADDRESS's, or a local one) and merge them")
    g.add_argument("--ray-retries", type=int, default=3, metavar="K", help="with --ray: times a lost shard runs again (default 3)")
    g.add_argument("--cpus-per-shard", type=float, default=1.0, metavar="C", help="with --ray: CPUs Ray reserves per shard, which its workers default to")
    g.add_argument("--slurm-script", metavar="FILE",
                   help="write an sbatch job array script (task I runs shard I, task 0 submits the merge) and exit")
    g.add_argument("--slurm-option", action="append", default=[], metavar="OPT",
                   help="with --slurm-script: an #SBATCH line (--partition=gpu, --time=4:00:00); repeatable")
    return p


def merge_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="envhub eval merge",
        description="Join the folders of an evaluation's shards (`envhub eval --shard I/N`) into one results table, "
        "report and statistics: the table one machine would have written.",
    )
    p.add_argument("out", metavar="OUT", help="the merged folder (new, or an earlier merge's)")
    p.add_argument("shards", metavar="SHARD", nargs="+", help="every shard's --out folder, each once")
    p.add_argument("--report", action="store_true", help="write OUT/report.html")
    return p


def merge_main(argv: list[str]) -> int:
    from .merge import merge, shards_markdown
    from .results import markdown

    args = merge_parser().parse_args(argv)
    try:
        results = merge(args.out, args.shards, report=args.report)
    except (BenchmarkError, FileExistsError) as e:
        print(f"envhub eval merge: error: {e}", file=sys.stderr)
        return 2
    sys.stdout.write(markdown(results))
    sys.stderr.write("\n" + shards_markdown(results))
    print(f"\nresults: {results['run']['out']}/results.json (merged from {len(args.shards)} shards)", file=sys.stderr)
    return 1 if results["summary"]["errors"] else 0


def _distributed(args: argparse.Namespace, argv: list[str], registry: Any) -> int:
    """--slurm-script and --ray: the shards' command line, written or run."""
    from .distribute import shard_argv
    from .evaluate import resolve
    from .results import markdown

    if args.shard is not None:
        raise BenchmarkError("--shard runs one shard; --ray and --slurm-script run them all (give --shards N)")
    if args.shards is None:
        raise BenchmarkError("--ray and --slurm-script need --shards N (how many slices the episodes are cut in)")
    if args.seeds is not None or args.record is not None:
        raise BenchmarkError("--seeds and --record run on one machine only (not with --ray or --slurm-script)")
    own = shard_argv(argv)
    if args.slurm_script is not None:
        from .slurm import slurm_script, write_slurm_script

        write_slurm_script(args.slurm_script, slurm_script(args.benchmark, own, args.out, args.shards, args.slurm_option))
        return 0
    if args.video:
        raise BenchmarkError("--video is not supported with --ray (a shard's videos stay on its node); use --slurm-script "
                             "with a shared --out, or --shard on each machine")
    from .ray_shards import run_on_ray

    bench, _ = resolve(args.benchmark, args.tasks, args.episodes, registry)
    results = run_on_ray(
        own, args.out, args.shards, bench=bench, address=args.ray or None, retries=args.ray_retries,
        cpus_per_shard=args.cpus_per_shard, resume=args.resume, report=args.report, progress=not args.quiet,
    )
    from .merge import shards_markdown

    sys.stdout.write(markdown(results))
    sys.stderr.write("\n" + shards_markdown(results))
    print(f"\nresults: {results['run']['out']}/results.json (merged from {args.shards} shards)", file=sys.stderr)
    return 1 if results["summary"]["errors"] else 0


#: The signals that stop an evaluation cleanly (SIGKILL cannot be caught: its workers and
#: policy process die with it, by the parent-death signal they are started with).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Stopped(KeyboardInterrupt):
    """A stop signal, raised in the main thread: the evaluation unwinds through its cleanup
    (sessions closed, the policy's process killed, the results file closed)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop(signum: int, frame: Any) -> None:
    # Once: the cleanup that follows is not interrupted by a second signal.
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    raise Stopped(signum)


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


def compare_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="envhub eval compare",
        description="Compare two runs of one benchmark episode by episode (paired by task and episode index): "
        "the success-rate difference B - A with its 95%% interval (Newcombe's method 10 for paired data) "
        "and McNemar's exact test, per task and overall.",
    )
    p.add_argument("run_a", metavar="RUN_A", help="a finished run's --out folder (or its results.json)")
    p.add_argument("run_b", metavar="RUN_B", help="the run to compare with it")
    p.add_argument("--html", metavar="FILE", help="also write the comparison as one HTML page")
    p.add_argument("--json", action="store_true", help="print the comparison as JSON instead of a table")
    return p


def compare_main(argv: list[str]) -> int:
    from .compare import compare, load_run, markdown, write_html

    args = compare_parser().parse_args(argv)
    try:
        comparison = compare(load_run(args.run_a), load_run(args.run_b))
    except BenchmarkError as e:
        print(f"envhub eval compare: error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(comparison, indent=1))
    else:
        sys.stdout.write(markdown(comparison))
    if args.html:
        print(f"report: {write_html(comparison, args.html)}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["compare"]:
        return compare_main(argv[1:])
    if argv[:1] == ["merge"]:
        return merge_main(argv[1:])
    if argv[:1] == ["status"]:
        from .watch import status_main

        return status_main(argv[1:])
    args = parser().parse_args(argv)
    registry = args.registry
    for s in STOP_SIGNALS:
        signal.signal(s, _stop)
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
        if args.out is None:
            print("envhub eval: error: give --out DIR (the folder the results are written to)", file=sys.stderr)
            return 2
        if args.ray is not None or args.slurm_script is not None:
            return _distributed(args, argv, registry)
        if args.shard is not None and args.seeds is not None:
            raise BenchmarkError("--shard runs a slice of one protocol's episodes: not with --seeds")
        if args.shards is not None:
            raise BenchmarkError("--shards N goes with --ray or --slurm-script (one shard: --shard I/N)")
        hubs = args.hubs if args.hubs in (None, "all", "local") else args.hubs.split(",")
        if args.seeds is not None:
            from .evaluate import evaluate_seeds, seeds_markdown

            run: Any = evaluate_seeds
            extra: dict[str, Any] = {"seeds": args.seeds}
        else:
            run, extra = evaluate, {}
        results = run(
            args.benchmark,
            args.policy,
            **extra,
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
            policy_timeout=args.policy_timeout or None,
            progress=not args.quiet,
            **({"shard": args.shard} if args.shard is not None else {}),
        )
    except (BenchmarkError, FileExistsError, ResumeError, RegistryError, PolicyLoadError) as e:
        print(f"envhub eval: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        signum = e.signum if isinstance(e, Stopped) else signal.SIGINT
        print(
            f"envhub eval: stopped by {signal.Signals(signum).name}; its envs and policy are down; "
            "--resume goes on from the last finished episode",
            file=sys.stderr,
        )
        return 128 + signum
    except Exception as e:
        from .runner import EvaluationStopped

        kind = "stopped" if isinstance(e, EvaluationStopped) else f"error: {type(e).__name__}"
        print(f"envhub eval: {kind}: {e}", file=sys.stderr)
        return 1
    from .results import markdown

    if args.seeds is not None:
        sys.stdout.write(seeds_markdown(results))
        print(f"\nresults: {os.path.abspath(args.out)}/seeds.json (and seed-*/results.json)", file=sys.stderr)
        return 1 if any(s["errors"] for s in results["seeds"]) else 0
    sys.stdout.write(markdown(results))
    print(f"\nresults: {results['run']['out']}/results.json", file=sys.stderr)
    return 1 if results["summary"]["errors"] else 0
