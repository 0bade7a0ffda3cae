"""`metaworld` (alias `meta_world`): Meta-World 3.x tasks with a Sawyer arm, through the ids
Meta-World registers in Gymnasium (`Meta-World/MT1`, ...)."""

from __future__ import annotations

from typing import Any

from .suites import SuiteAdapter, gym_make, unknown_id

#: The Meta-World id an entry names by its task alone (`reach-v3`).
MT1 = "Meta-World/MT1"


class MetaWorldAdapter(SuiteAdapter):
    """Meta-World tasks: the env id is a Meta-World Gymnasium id (`Meta-World/MT1`, with the
    task in the option `env_name`, e.g. `reach-v3`) or a task name alone (`reach-v3`, for
    MT1). Meta-World draws its set of goal positions (tasks) and seeds the env when it is
    made, from the option `seed`, and ignores reset seeds; envhub makes env `i` of a session
    with `seed` = the option (else the session's seed, else 0) + `i`, so every env is
    reproducible. The other options go to Meta-World (`reward_function_version`,
    `terminate_on_success`, `task_select`, `width`, `height`, `camera_name`, ...)."""

    name = "metaworld"
    frameworks = ["metaworld", "meta_world"]
    requires = ["metaworld", "mujoco"]
    description = "Meta-World 3.x manipulation tasks (Sawyer arm, MuJoCo 3.3), hosted in a Python worker"
    install_hint = "pip install metaworld==3.1.1 mujoco==3.3.0 packaging (the catalog's Python environment `metaworld`)"
    mujoco_series = ("3.3.",)
    python_env = "metaworld"

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym
        import metaworld

        kwargs = dict(config.extra)
        if not env_id.startswith("Meta-World/"):
            if env_id not in metaworld.ALL_V3_ENVIRONMENTS:
                raise unknown_id(
                    "Meta-World",
                    env_id,
                    sorted(metaworld.ALL_V3_ENVIRONMENTS),
                    "a task name such as `reach-v3` (MT1), or `Meta-World/MT1` with the option `env_name`",
                )
            if kwargs.setdefault("env_name", env_id) != env_id:
                raise ValueError(
                    f"`{env_id}` names a task and the option `env_name` names `{kwargs['env_name']}`\n"
                    "hint: name the task in one place only"
                )
            env_id = MT1
        if env_id not in gym.registry:
            ids = [i for i in gym.registry if i.startswith("Meta-World/")]
            raise unknown_id("Meta-World", env_id, ids, f"Meta-World registers: {', '.join(ids)}")
        if env_id == MT1 and kwargs.get("env_name") not in metaworld.ALL_V3_ENVIRONMENTS:
            raise unknown_id(
                "Meta-World MT1",
                str(kwargs.get("env_name")),
                sorted(metaworld.ALL_V3_ENVIRONMENTS),
                "set the option `env_name` to a task: "
                + ", ".join(sorted(metaworld.ALL_V3_ENVIRONMENTS)[:8])
                + ", ...",
            )
        base = kwargs.get("seed", config.seed if config.seed is not None else 0)
        if isinstance(base, bool) or not isinstance(base, int):
            raise TypeError(f"Meta-World option `seed` must be an integer, not {base!r}")
        kwargs["seed"] = base + int(config.env_index or 0)
        return gym_make(env_id, config, kwargs)
