"""Reference trajectories of Gymnasium's MuJoCo v5 envs, for envhub-mujoco's parity test.

For each run (env id, constructor kwargs, seed, steps) this makes the env with `gym.make` (so
Gymnasium's `TimeLimit` truncates), resets it with the seed and records the initial
observation and state (`qpos`, `qvel`), then takes random float32 actions uniform in the action
space, recording per step the action, observation, reward, `terminated` and `truncated`. When an
episode ends it resets without a seed (the generator continues, as in a real episode loop) and
records the new initial observation and state. Each run also records the env's
`metadata["render_fps"]`.

A run with an action scale multiplies every action by it, so that most lie beyond the bounds
(Gymnasium sets `data.ctrl` to them, MuJoCo clamps `ctrl` to `ctrlrange`, and the control cost
uses the action as given); it records each step's info too.

A run with `"set_state": true` instead starts from a state it sets itself after the seeded reset
(the seeded one, perturbed), through `MujocoEnv.set_state`: the Rust side passes that state as
the `qpos`/`qvel` reset options.

Run by `adapters/mujoco/tests/gymnasium_parity.rs`; by hand:
    python tests/python/support/mujoco_reference.py [--steps N] > reference.json
"""

from __future__ import annotations

import argparse
import json
import sys

import gymnasium as gym
import numpy as np

V5 = [
    "Ant-v5",
    "HalfCheetah-v5",
    "Hopper-v5",
    "Walker2d-v5",
    "Humanoid-v5",
    "HumanoidStandup-v5",
    "Swimmer-v5",
    "Reacher-v5",
    "Pusher-v5",
    "InvertedPendulum-v5",
    "InvertedDoublePendulum-v5",
]

# (env id, kwargs, seed, steps, set_state): every env for 1000 steps from a seeded reset and
# briefly from a given state, plus the kwargs users set most.
RUNS = (
    [(env_id, {}, 0, 1000, False) for env_id in V5]
    + [(env_id, {}, 1, 60, True) for env_id in V5]
    + [
        ("Ant-v5", {"ctrl_cost_weight": 0.1, "contact_cost_weight": 0.0,
                    "include_cfrc_ext_in_observation": False,
                    "healthy_z_range": [0.3, 0.9], "reset_noise_scale": 0.2}, 2, 300, False),
        ("HalfCheetah-v5", {"forward_reward_weight": 2.0,
                            "exclude_current_positions_from_observation": False}, 3, 200, False),
        ("Hopper-v5", {"terminate_when_unhealthy": False, "healthy_z_range": [0.8, "inf"],
                       "frame_skip": 2}, 4, 300, False),
        ("Walker2d-v5", {"healthy_angle_range": [-0.5, 0.5], "reset_noise_scale": 0.1}, 5, 300,
         False),
        ("Humanoid-v5", {"include_cinert_in_observation": False,
                         "include_cvel_in_observation": False,
                         "contact_cost_weight": 1e-4, "healthy_z_range": [0.9, 2.1]}, 6, 300,
         False),
        ("Swimmer-v5", {"exclude_current_positions_from_observation": False}, 7, 200, False),
        ("Reacher-v5", {"reward_control_weight": 0.5}, 8, 200, False),
        ("InvertedDoublePendulum-v5", {"healthy_reward": 5.0, "reset_noise_scale": 0.3}, 9, 300,
         False),
    ]
)


# (env id, kwargs, seed, steps, action scale): actions three times the box, two thirds of them
# beyond its bounds.
OUT_OF_RANGE_RUNS = [
    ("Ant-v5", {}, 11, 300, 3.0),
    ("HalfCheetah-v5", {}, 12, 300, 3.0),
    ("Hopper-v5", {}, 13, 300, 3.0),
]


def python_kwargs(kwargs: dict) -> dict:
    """JSON kwargs as Gymnasium takes them: lists become tuples, "inf" becomes a float."""
    out = {}
    for k, v in kwargs.items():
        if isinstance(v, list):
            v = tuple(float(x) for x in v)
        out[k] = v
    return out


def floats(a) -> list[float]:
    return np.asarray(a, dtype=np.float64).ravel().tolist()


def record(
    env_id: str, kwargs: dict, seed: int, steps: int, set_state: bool, scale: float = 1.0
) -> dict:
    env = gym.make(env_id, **python_kwargs(kwargs))
    raw = env.unwrapped
    env.action_space.seed(seed)
    rng = np.random.default_rng(seed + 1000)
    obs, _ = env.reset(seed=seed)
    run = {"env_id": env_id, "kwargs": kwargs, "seed": seed,
           "max_episode_steps": env.spec.max_episode_steps,
           "render_fps": env.metadata["render_fps"], "action_scale": scale}
    if set_state:
        qpos = raw.data.qpos.copy() + 0.01 * rng.standard_normal(raw.model.nq)
        qvel = raw.data.qvel.copy() + 0.1 * rng.standard_normal(raw.model.nv)
        raw.set_state(qpos, qvel)
        obs = raw._get_obs()
        run["options"] = {"qpos": floats(qpos), "qvel": floats(qvel)}
    run["reset_obs"] = floats(obs)
    run["reset_qpos"] = floats(raw.data.qpos)
    run["reset_qvel"] = floats(raw.data.qvel)
    low, high = env.action_space.low, env.action_space.high
    out_steps = []
    for _ in range(steps):
        action = rng.uniform(low, high).astype(np.float32)
        if scale != 1.0:
            action = action * np.float32(scale)
        obs, reward, terminated, truncated, info = env.step(action)
        step = {
            "action": [float(a) for a in action],
            "obs": floats(obs),
            "reward": float(reward),
            "terminated": bool(terminated),
            "truncated": bool(truncated),
        }
        if scale != 1.0:
            step["info"] = {k: float(v) for k, v in info.items()}
        if terminated or truncated:
            obs, _ = env.reset()
            step["reset_obs"] = floats(obs)
            step["reset_qpos"] = floats(raw.data.qpos)
            step["reset_qvel"] = floats(raw.data.qvel)
        out_steps.append(step)
    run["steps"] = out_steps
    env.close()
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=None, help="override every run's length")
    args = parser.parse_args()
    runs = [
        record(env_id, kwargs, seed, args.steps or steps, set_state)
        for env_id, kwargs, seed, steps, set_state in RUNS
    ] + [
        record(env_id, kwargs, seed, args.steps or steps, False, scale)
        for env_id, kwargs, seed, steps, scale in OUT_OF_RANGE_RUNS
    ]
    json.dump({"gymnasium": gym.__version__, "runs": runs}, sys.stdout)


if __name__ == "__main__":
    main()
