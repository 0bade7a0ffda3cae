"""Steps a LeRobot env config's vector env with fixed actions and dumps what LeRobot's
evaluation would see, for test_lerobot_plugin.py.

Runs in a LeRobot interpreter (LeRobot's own env with its suite installed, or the plugin's
with none): `python lerobot_rollout.py SPEC.json OUT.npz`, where SPEC names the env type and
its options (`{"type": "metaworld", "config": {"task": "push-v3"}, "n_envs": 2, "seeds":
[..], "steps": N, "async": false}`). Writes the first observation after LeRobot's
`preprocess_observation` and the env config's processors (`first/<key>`), the frames
`render` gives then (`render`), and per step: rewards, terminated, truncated, `is_success`
as the rollout reads it, and a digest of each env's raw observation (`obs_digest`).
"""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np


def actions(step: int, n: int, dim: int, seed: int = 0) -> np.ndarray:
    """A fixed smooth action per step and env, in [-1, 1]."""
    t = np.arange(dim, dtype=np.float64)
    rows = [np.sin(0.05 * step * (1 + 0.3 * t) + 0.7 * i + seed) for i in range(n)]
    return np.stack(rows).astype(np.float32)


def digest(obs, i: int) -> bytes:
    h = hashlib.sha256()

    def walk(value, key: str) -> None:
        if isinstance(value, dict):
            for k in sorted(value):
                walk(value[k], f"{key}/{k}")
        else:
            a = np.ascontiguousarray(np.asarray(value)[i])
            h.update(key.encode() + str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())

    walk(obs, "")
    return h.digest()


def successes(info: dict, n: int) -> list[bool]:
    """`is_success` as `lerobot_eval.rollout` reads it from a step's info."""
    if "final_info" in info and isinstance(info["final_info"], dict):
        value = info["final_info"].get("is_success", [False] * n)
        return [bool(v) for v in np.asarray(value).reshape(-1)]
    if "is_success" in info:
        return [bool(v) for v in np.asarray(info["is_success"]).reshape(-1)]
    return [False] * n


def main(spec_path: str, out: str) -> None:
    from lerobot.envs.factory import make_env, make_env_config
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION, preprocess_observation
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    spec = json.loads(open(spec_path).read())
    cfg = make_env_config(spec["type"], **spec.get("config", {}))
    n = int(spec["n_envs"])
    envs = make_env(cfg, n_envs=n, use_async_envs=bool(spec.get("async", False)))
    group = next(iter(envs))
    env = envs[group][min(envs[group])]
    arrays: dict[str, np.ndarray] = {}
    try:
        obs, _ = env.reset(seed=spec["seeds"], options={NEW_ROLLOUT_OPTION: True})
        env_pre, _ = cfg.get_env_processors()
        first = env_pre(preprocess_observation(obs))
        for key, value in first.items():
            if hasattr(value, "numpy"):
                arrays[f"first/{key}"] = value.numpy()
        arrays["render"] = np.stack(env.call("render"))
        dim = int(cfg.features["action"].shape[0])
        rewards, terminated, truncated, success, digests = [], [], [], [], []
        digests.append([digest(obs, i) for i in range(n)])
        for step in range(int(spec["steps"])):
            obs, reward, term, trunc, info = env.step(actions(step, n, dim))
            rewards.append(np.asarray(reward, dtype=np.float64))
            terminated.append(np.asarray(term, dtype=bool))
            truncated.append(np.asarray(trunc, dtype=bool))
            success.append(successes(info, n))
            digests.append([digest(obs, i) for i in range(n)])
        arrays["rewards"] = np.stack(rewards)
        arrays["terminated"] = np.stack(terminated)
        arrays["truncated"] = np.stack(truncated)
        arrays["success"] = np.array(success, dtype=bool)
        arrays["obs_digest"] = np.array([[np.frombuffer(d, dtype=np.uint8) for d in row] for row in digests])
        arrays["max_episode_steps"] = np.array(env.call("_max_episode_steps"))
        arrays["task_description"] = np.array(env.call("task_description"))
        arrays["render_fps"] = np.array(env.unwrapped.metadata["render_fps"])
    finally:
        env.close()
    np.savez(out, **arrays)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
