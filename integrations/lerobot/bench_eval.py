"""`lerobot-eval` episodes per minute through the plugin (`--env.type=envhub`) against
LeRobot's own env (`--env.type=libero` or `metaworld`: the suite in LeRobot's interpreter,
stepped in Gymnasium's `AsyncVectorEnv`), same policy, seed, batch and machine, in one run:

    .venv/bin/python integrations/lerobot/bench_eval.py --suite libero --batch 5 --episodes 10
    .venv/bin/python integrations/lerobot/bench_eval.py --suite metaworld --task push-v3

LIBERO's horizon and camera size are LeRobot's own options (`--episode-length`, `--size`);
the defaults keep a run within minutes on a small machine. `--workers` sets envhub's worker
processes (`--env.workers`); `--sides envhub` runs one side alone (where the other does not
fit in memory: LeRobot's LIBERO takes one process of about 2.4 GB per env, so batch 10 needs
about 25 GB). The policy is a random-init ACT saved with LeRobot's `save_pretrained` (or
`--policy DIR`). Both sides write the videos `lerobot-eval` writes (its first 10 episodes,
rendered every step). Prints one JSON object: each side's wall time, episodes per minute, the
ratio, and whether the per-episode results of `eval_info.json` and the videos are equal.
Uses the interpreters the tests use (tests/python/support/lerobot_envs.py): .venv-lerobot,
and the reference venv in the user cache (built on first use).

Where the time goes: every side's process tree (`lerobot-eval` and its descendants: envhub's
hub and workers, or `AsyncVectorEnv`'s processes) is read from /proc twice a second, and each
process's CPU seconds and the tree's peak memory are reported by role (`cpu_s`, `peak_rss_gb`).
`--profile DIR` also samples every side's processes with py-spy (the `PY_SPY` binary, else
`py-spy` on PATH; native frames included; slower, so a separate run from the one timed) and
splits each side's samples and CPU seconds by whose code they are in (`profile_split.py`).
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SUPPORT = REPO / "tests" / "python" / "support"
sys.path.insert(0, str(SUPPORT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_procs  # noqa: E402
import lerobot_envs  # noqa: E402
import profile_split  # noqa: E402

#: py-spy's binary (`--profile`): `PY_SPY`, else on PATH.
PY_SPY = os.environ.get("PY_SPY") or shutil.which("py-spy") or "py-spy"

EPISODE_KEYS = ("sum_rewards", "max_rewards", "successes")


def lerobot_eval(
    python: Path, site: Path | None, args: list[str], out: Path, profile: Path | None = None
) -> tuple[float, dict, dict]:
    """Runs `lerobot-eval` (under py-spy where `profile` names its output): its wall time,
    its `eval_info.json`, and what its process tree cost (bench_procs.py)."""
    env = {**lerobot_envs.user_env(site), **lerobot_envs.libero_config(python)}
    command = [str(python), "-m", "lerobot.scripts.lerobot_eval", *args, f"--output_dir={out}"]
    if profile is not None:
        spy = ["record", "--subprocesses", "--native", "--rate", "20", "--format", "raw", "-o", str(profile)]
        command = [PY_SPY, *spy, "--", *command]
    log = out.parent / "lerobot-eval.log"
    start = time.monotonic()
    with open(log, "w") as sink:
        proc = subprocess.Popen(command, stdout=sink, stderr=subprocess.STDOUT, env=env, cwd=out.parent)
        tree = bench_procs.Tree(proc.pid)
        tree.start()
        proc.wait()
    wall = time.monotonic() - start
    cost = tree.stop()
    if proc.returncode != 0:
        sys.exit(f"lerobot-eval failed:\n{log.read_text()[-4000:]}")
    return wall, json.loads((out / "eval_info.json").read_text()), cost


def episodes(info: dict) -> list[dict]:
    """Each task's per-episode results, in task order."""
    return [
        {"task": [t["task_group"], t["task_id"]], **{k: t["metrics"][k] for k in EPISODE_KEYS}} for t in info["per_task"]
    ]


def same_videos(a: Path, b: Path) -> bool:
    mine = sorted(p.relative_to(a) for p in a.rglob("*.mp4"))
    theirs = sorted(p.relative_to(b) for p in b.rglob("*.mp4"))
    return bool(mine) and mine == theirs and all(filecmp.cmp(a / p, b / p, shallow=False) for p in mine)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", choices=("libero", "metaworld"), default="libero")
    parser.add_argument("--task", help="LIBERO: a suite (libero_spatial); Meta-World: a task (push-v3)")
    parser.add_argument("--task-id", type=int, default=0, help="LIBERO: the task's index in its suite")
    parser.add_argument("--size", type=int, default=128, help="LIBERO: camera height and width (LeRobot's default 360)")
    parser.add_argument("--episode-length", type=int, default=60, help="LIBERO: steps per episode (0: LeRobot's horizon)")
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--policy", type=Path, help="a saved policy folder (default: a random-init ACT)")
    parser.add_argument("--workers", type=int, help="envhub's worker processes (--env.workers; default the plugin's: balanced over the cores)")
    parser.add_argument("--sides", default="envhub,lerobot", help="which sides to run, in order")
    parser.add_argument("--profile", type=Path, help="a folder for each side's py-spy samples (slower: not a timing run)")
    args = parser.parse_args()

    python = lerobot_envs.lerobot_python()
    if args.suite == "libero":
        task = args.task or "libero_spatial"
        config = {
            "task": task,
            "task_ids": [args.task_id],
            "observation_height": args.size,
            "observation_width": args.size,
            **({"episode_length": args.episode_length} if args.episode_length else {}),
        }
        reference = lerobot_envs.reference_venv(
            python, "libero", lerobot_envs.LIBERO_REFERENCE, lerobot_envs.LIBERO_FIRST
        )
    else:
        task = args.task or "push-v3"
        config = {"task": task}
        reference = lerobot_envs.reference_venv(python, "metaworld", lerobot_envs.METAWORLD_REFERENCE)
    env_args = [f"--env.{k}={json.dumps(v) if isinstance(v, list) else v}" for k, v in config.items()]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        site = lerobot_envs.install_plugin(python, tmp / "plugin")
        policy = args.policy
        if policy is None:
            policy = tmp / "policy"
            spec = tmp / "policy.json"
            spec.write_text(json.dumps({"type": "envhub", "config": config}))
            subprocess.run(
                [str(python), str(SUPPORT / "lerobot_policy.py"), str(spec), str(policy)],
                check=True,
                env=lerobot_envs.user_env(site),
                capture_output=True,
            )
        common = [
            f"--policy.path={policy}",
            "--policy.device=cpu",
            *env_args,
            f"--eval.batch_size={args.batch}",
            f"--eval.n_episodes={args.episodes}",
            "--seed=1000",
        ]
        sides = {
            "envhub": (python, site, ["--env.type=envhub", *([f"--env.workers={args.workers}"] if args.workers else [])]),
            "lerobot": (reference, None, [f"--env.type={args.suite}"]),
        }
        if args.profile:
            args.profile.mkdir(parents=True, exist_ok=True)
        results, infos = {}, {}
        for name in args.sides.split(","):
            py, s, env_args = sides[name]
            (tmp / name).mkdir()
            profile = args.profile / f"{name}.txt" if args.profile else None
            wall, infos[name], cost = lerobot_eval(py, s, [*common, *env_args], tmp / name / "out", profile)
            n = infos[name]["overall"]["n_episodes"]
            results[name] = {"wall_s": round(wall, 1), "episodes": n, "episodes_per_min": round(60 * n / wall, 2), **cost}
            if profile is not None:
                shares = profile_split.split(profile)
                results[name]["profile"] = shares
                results[name]["profile_cpu_s"] = profile_split.cpu_seconds(shares, cost["cpu_s"])
            print(json.dumps({name: results[name]}), file=sys.stderr, flush=True)
        summary = {"suite": args.suite, "env": config, "batch": args.batch, "workers": args.workers, **results}
        if len(results) == 2:
            ratio = results["envhub"]["episodes_per_min"] / results["lerobot"]["episodes_per_min"]
            summary.update(
                ratio=round(ratio, 2),
                same_episodes=episodes(infos["envhub"]) == episodes(infos["lerobot"]),
                same_videos=same_videos(tmp / "envhub" / "out" / "videos", tmp / "lerobot" / "out" / "videos"),
            )
        summary["episodes"] = {name: episodes(info) for name, info in infos.items()}
        print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
