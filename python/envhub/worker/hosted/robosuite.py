"""`robosuite`: robosuite 1.5's manipulation tasks (Lift, Stack, Door, NutAssembly,
PickPlace, the two-arm tasks), state and camera images as one Dict observation."""

from __future__ import annotations

import os
from typing import Any, cast

import gymnasium as gym

from .suites import SuiteAdapter, unknown_id


class RobosuiteAdapter(SuiteAdapter):
    """robosuite tasks by robosuite's env name (`Lift`, `TwoArmHandover`, ...); the entry's
    options go to `robosuite.make` (`robots`, `reward_shaping`, `control_freq`,
    `controller_configs`, `horizon`, ...). Observations: robosuite's dict (proprio and object
    state; `obs_keys` keeps only the keys it lists). Cameras: `camera_names` (one name or a
    list), `camera_heights`, `camera_widths` add `<camera>_image` uint8 (H, W, 3) as robosuite
    renders them offscreen (MuJoCo's EGL: a GPU's or Mesa's), upside down unless robosuite's
    `IMAGE_CONVENTION` macro says otherwise. `reset(seed=s)` reseeds robosuite's generator
    (`env.rng`, which places the objects) and numpy's global one; the episode is truncated
    at robosuite's `horizon` (default 1000); `info["success"]` is robosuite's `_check_success()`."""

    name = "robosuite"
    frameworks = ["robosuite"]
    requires = ["robosuite", "mujoco"]
    description = "robosuite 1.5 manipulation tasks (Panda and other arms, MuJoCo 3.3), hosted in a Python worker"
    install_hint = "pip install robosuite==1.5.2 mujoco==3.3.0 (the catalog's Python environment `robosuite`)"
    mujoco_series = ("3.3.",)
    python_env = "robosuite"

    def make(self, env_id: str, config: Any) -> Any:
        if config.render_mode is not None:
            raise ValueError(
                f"robosuite envs take no render_mode (got {config.render_mode!r}): cameras render into the "
                "observation, `<camera>_image`\nhint: leave render_mode unset and set the option `camera_names` "
                "(with `camera_heights`/`camera_widths`)"
            )
        # Offscreen rendering through EGL (a GPU's or Mesa's) unless the user chose.
        os.environ.setdefault("MUJOCO_GL", "egl")
        os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
        import robosuite

        from . import compiled_models, sensor_checks

        # Hard resets (the default) compile the same robot, and often the same scene, again,
        # and render each camera to learn its shape again.
        compiled_models.install()
        sensor_checks.install()
        sensor_checks.freeze_imports()

        if env_id not in robosuite.ALL_ENVIRONMENTS:
            names = sorted(robosuite.ALL_ENVIRONMENTS)
            raise unknown_id("robosuite", env_id, names, f"robosuite's envs: {', '.join(names)}")
        return RobosuiteEnv(env_id, dict(config.extra))


def make_kwargs(options: dict[str, Any]) -> tuple[dict[str, Any], list[str] | None]:
    """`robosuite.make`'s keyword arguments for an entry's options, and the observation keys
    to keep (None: every numeric key). Cameras are on when `camera_names` is given."""
    options = dict(options)
    keys = options.pop("obs_keys", None)
    cameras = options.get("camera_names")
    use_cameras = bool(options.setdefault("use_camera_obs", cameras is not None))
    if use_cameras and cameras is None:
        options["camera_names"] = "agentview"
    options.setdefault("has_renderer", False)
    options.setdefault("has_offscreen_renderer", use_cameras)
    options.setdefault("robots", "Panda")
    # robosuite refuses a step after its horizon unless told to ignore it; the adapter
    # truncates there itself (Gymnasium's contract), so the step limit stays the one cut.
    options["ignore_done"] = True
    return options, keys


def reseed(env: Any, seed: int) -> None:
    """Reseeds robosuite's generator in place (its placement samplers hold the same object)
    and numpy's global one (what robosuite's own `GymWrapper.reset(seed=...)` seeds)."""
    import numpy as np

    env.rng.bit_generator.state = np.random.default_rng(seed).bit_generator.state
    np.random.seed(seed)


class RobosuiteEnv(gym.Env):
    """Gymnasium's contract over a robosuite env (`reset() -> obs`, `step -> (obs, reward,
    done, info)`); the spaces come from the first observation."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, name: str, options: dict[str, Any]) -> None:
        import robosuite

        from .libero_spec import action_space, control_rate, observation_space, outside

        kwargs, keys = make_kwargs(options)
        self.env = robosuite.make(name, **kwargs)
        # One step is one control period: what a recording's timestamps count in.
        self.metadata = {**self.metadata, "render_fps": control_rate(self.env)}
        obs = self.env.reset()
        if keys is not None:
            missing = sorted(set(keys) - set(obs))
            if missing:
                raise LookupError(f"robosuite `{name}` has no observation {missing}\nhint: its keys: {', '.join(obs)}")
            obs = {k: obs[k] for k in keys}
        self.observation_space = observation_space(obs)
        self.action_space = action_space(*self.env.action_spec)
        bad = outside(self.observation_space, obs)
        if bad:
            raise ValueError(f"robosuite's first observation is outside the space built from it at {bad}")
        self.horizon = int(self.env.horizon)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if options:
            raise ValueError(f"robosuite envs take no reset options (got {sorted(options)})\nhint: reset(seed=...)")
        if seed is not None:
            reseed(self.env, seed)
        return self._obs(self.env.reset()), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        import numpy as np

        obs, reward, _, _ = self.env.step(np.asarray(action, dtype=np.float64))
        success = bool(self.env._check_success())
        return self._obs(obs), float(reward), False, self.env.timestep >= self.horizon, {"success": success}

    def _obs(self, obs: dict[str, Any]) -> dict[str, Any]:
        return {k: obs[k] for k in cast(gym.spaces.Dict, self.observation_space).spaces}

    def close(self) -> None:
        self.env.close()
