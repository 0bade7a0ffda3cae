"""Reference trajectories of Gymnasium's classic-control envs, for envhub-classic's parity test.

For each run (env id, constructor kwargs, reset options, seed) this resets the unwrapped
Gymnasium env with the seed, then takes random actions; before every step it records the env's
internal state (`env.unwrapped.state`), and after it the action, observation, reward and
`terminated`. On termination, or after the run's episode length limit (as `TimeLimit` would
truncate), it resets again without a seed (the env's generator continues, as in a real episode
loop) and records the new initial state under `reset_state`. Each run also records the env's
`metadata["render_fps"]`. Runs with an action scale multiply every box action by it, so most
actions lie beyond the bounds (Gymnasium passes them to the env, which clips them; envhub
must do the same). It prints one JSON document on stdout.

Run by `adapters/classic/tests/gymnasium_parity.rs`; by hand:
    python tests/python/support/classic_reference.py [--steps N] > reference.json
"""

from __future__ import annotations

import argparse
import json
import sys

import gymnasium as gym
import numpy as np

# (env id, kwargs for gym.make, reset options or None, seeds, steps, episode length limit)
RUNS = [
    ("CartPole-v1", {}, None, [0, 1, 2], 300, 500),
    ("CartPole-v1", {"sutton_barto_reward": True}, {"low": -0.1, "high": 0.1}, [3], 300, 500),
    ("Pendulum-v1", {}, None, [0, 1], 300, 200),
    ("Pendulum-v1", {"g": 9.81}, {"x_init": 1.0, "y_init": 0.5}, [2], 300, 100),
    ("MountainCar-v0", {}, None, [0, 1], 300, 200),
    # Short episodes that start near the goal: many terminations and resets.
    ("MountainCar-v0", {}, {"low": 0.45, "high": 0.6}, [2], 300, 10),
    ("MountainCar-v0", {"goal_velocity": 0.001}, {"low": 0.45, "high": 0.6}, [3], 300, 10),
    ("MountainCarContinuous-v0", {}, None, [0, 1], 300, 999),
    ("MountainCarContinuous-v0", {}, {"low": 0.4, "high": 0.6}, [2], 300, 10),
    ("MountainCarContinuous-v0", {"goal_velocity": 0.001}, {"low": 0.4, "high": 0.6}, [3], 300, 10),
    ("Acrobot-v1", {}, None, [0, 1, 2], 1000, 500),
    ("Acrobot-v1", {}, {"low": -0.2, "high": 0.2}, [3], 1000, 500),
    # Wide initial angles: frequent terminations, and angles that need wrapping.
    ("Acrobot-v1", {}, {"low": -2.5, "high": 2.5}, [4], 500, 50),
]

# (env id, kwargs, reset options, seeds, steps, episode length limit, action scale): actions
# three times the box, two thirds of them beyond its bounds.
OUT_OF_RANGE_RUNS = [
    ("Pendulum-v1", {}, None, [5, 6], 300, 200, 3.0),
    ("MountainCarContinuous-v0", {}, None, [5], 300, 999, 3.0),
    ("MountainCarContinuous-v0", {}, {"low": 0.4, "high": 0.6}, [6], 300, 10, 3.0),
]


def state_of(env: gym.Env) -> tuple[list[float], str]:
    state = np.asarray(env.unwrapped.state)
    return state.astype(np.float64).tolist(), state.dtype.name


def action_of(env: gym.Env, rng: np.random.Generator, i: int, scale: float):
    """A random action; every seventh one of a box is a bound, so clipping edges are exercised.
    With a scale other than 1, box actions are multiplied by it, and every eleventh is the
    float32 just beyond a bound."""
    space = env.action_space
    if isinstance(space, gym.spaces.Discrete):
        return int(space.sample())
    if scale != 1.0 and i % 11 == 5:
        low, high = space.low[0], space.high[0]
        edge = np.nextafter(low, -np.inf) if rng.random() < 0.5 else np.nextafter(high, np.inf)
        return np.array([edge], dtype=np.float32)
    if i % 7 == 3:
        action = np.array([space.low[0] if rng.random() < 0.5 else space.high[0]], dtype=np.float32)
    else:
        action = space.sample()
    return action * np.float32(scale) if scale != 1.0 else action


def record(
    env_id: str,
    kwargs: dict,
    options: dict | None,
    seed: int,
    steps: int,
    limit: int,
    scale: float = 1.0,
) -> dict:
    env = gym.make(env_id, **kwargs).unwrapped  # no TimeLimit: runs go past the limit
    env.action_space.seed(seed)
    rng = np.random.default_rng(seed + 1000)
    obs, _ = env.reset(seed=seed, options=options)
    reset_obs = np.asarray(obs, dtype=np.float32).tolist()
    reset_state, reset_dtype = state_of(env)
    out_steps = []
    episode_steps = 0
    for i in range(steps):
        state, dtype = state_of(env)
        action = action_of(env, rng, i, scale)
        obs, reward, terminated, _, _ = env.step(action)
        step = {
            "state": state,
            "state_dtype": dtype,
            "action": action if isinstance(action, int) else [float(a) for a in action],
            "obs": np.asarray(obs, dtype=np.float32).tolist(),
            "reward": float(reward),
            "terminated": bool(terminated),
        }
        episode_steps += 1
        if terminated or episode_steps == limit:
            episode_steps = 0
            obs, _ = env.reset(options=options)
            step["reset_state"], _ = state_of(env)
            step["reset_obs"] = np.asarray(obs, dtype=np.float32).tolist()
        out_steps.append(step)
    return {
        "env_id": env_id,
        "kwargs": kwargs,
        "render_fps": env.metadata["render_fps"],
        "options": options or {},
        "seed": seed,
        "action_scale": scale,
        "reset_state": reset_state,
        "reset_state_dtype": reset_dtype,
        "reset_obs": reset_obs,
        "steps": out_steps,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, help="steps per run (default: per env)")
    args = parser.parse_args()
    runs = []
    for env_id, kwargs, options, seeds, steps, limit in RUNS:
        for seed in seeds:
            runs.append(record(env_id, kwargs, options, seed, args.steps or steps, limit))
    for env_id, kwargs, options, seeds, steps, limit, scale in OUT_OF_RANGE_RUNS:
        for seed in seeds:
            runs.append(record(env_id, kwargs, options, seed, args.steps or steps, limit, scale))
    json.dump({"gymnasium": gym.__version__, "numpy": np.__version__, "runs": runs}, sys.stdout)


if __name__ == "__main__":
    main()
