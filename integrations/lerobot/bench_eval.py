"""`lerobot-eval` episodes per minute through the plugin (`--env.type=envhub`) against
LeRobot's own env (`--env.type=metaworld`, the suite in LeRobot's interpreter, stepped in
Gymnasium's `AsyncVectorEnv`), same policy, seed, batch and machine, in one run:

    .venv/bin/python integrations/lerobot/bench_eval.py --task push-v3 --batch 10 --episodes 10

The policy is a random-init ACT saved with LeRobot's `save_pretrained` (or `--policy DIR`).
Both sides write the videos `lerobot-eval` writes (its first 10 episodes, rendered each step).
Prints one JSON object: each side's wall time, episodes per minute, the ratio, and whether
the per-episode results of `eval_info.json` are equal. Uses the interpreters the tests use
(tests/python/lerobot_envs.py): .venv-lerobot-next, and the reference venv in the user cache.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "python"))

import lerobot_envs  # noqa: E402


def lerobot_eval(python: Path, site: Path | None, args: list[str], out: Path) -> tuple[float, dict]:
    start = time.monotonic()
    done = subprocess.run(
        [str(python), "-m", "lerobot.scripts.lerobot_eval", *args, f"--output_dir={out}"],
        capture_output=True,
        text=True,
        env=lerobot_envs.user_env(site),
        cwd=out.parent,
    )
    wall = time.monotonic() - start
    if done.returncode != 0:
        sys.exit(f"lerobot-eval failed:\n{done.stderr[-4000:]}")
    return wall, json.loads((out / "eval_info.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="push-v3", help="a Meta-World task")
    parser.add_argument("--batch", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--policy", type=Path, help="a saved policy folder (default: a random-init ACT)")
    args = parser.parse_args()

    python = lerobot_envs.lerobot_python()
    reference = lerobot_envs.reference_venv(python, "metaworld", lerobot_envs.METAWORLD_REFERENCE)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        site = lerobot_envs.install_plugin(python, tmp / "plugin")
        policy = args.policy
        if policy is None:
            policy = tmp / "policy"
            spec = tmp / "policy.json"
            spec.write_text(json.dumps({"type": "envhub", "config": {"task": args.task}}))
            subprocess.run(
                [str(python), str(REPO / "tests" / "python" / "lerobot_policy.py"), str(spec), str(policy)],
                check=True,
                env=lerobot_envs.user_env(site),
                capture_output=True,
            )
        common = [
            f"--policy.path={policy}",
            "--policy.device=cpu",
            f"--env.task={args.task}",
            f"--eval.batch_size={args.batch}",
            f"--eval.n_episodes={args.episodes}",
            "--seed=1000",
        ]
        results = {}
        for name, py, s, env_type in (("envhub", python, site, "envhub"), ("lerobot", reference, None, "metaworld")):
            (tmp / name).mkdir()
            wall, info = lerobot_eval(py, s, [*common, f"--env.type={env_type}"], tmp / name / "out")
            episodes = info["overall"]["n_episodes"]
            results[name] = {
                "wall_s": round(wall, 1),
                "episodes": episodes,
                "episodes_per_min": round(60 * episodes / wall, 2),
                "per_task": info["per_task"],
            }
        same = [t["metrics"]["sum_rewards"] for t in results["envhub"]["per_task"]] == [
            t["metrics"]["sum_rewards"] for t in results["lerobot"]["per_task"]
        ]
        for r in results.values():
            r.pop("per_task")
        ratio = results["envhub"]["episodes_per_min"] / results["lerobot"]["episodes_per_min"]
        print(
            json.dumps(
                {"task": args.task, "batch": args.batch, **results, "ratio": round(ratio, 2), "same_rewards": same},
                indent=2,
            )
        )


if __name__ == "__main__":
    main()
