"""`dm_control` (alias `dmc`): DeepMind Control Suite tasks through Shimmy's Gymnasium ids
(`dm_control/cheetah-run-v0`)."""

from __future__ import annotations

from typing import Any

from .suites import SuiteAdapter, gym_make, unknown_id

PREFIX = "dm_control/"


class DmControlAdapter(SuiteAdapter):
    """dm_control's suite (and its locomotion and manipulation tasks) as Shimmy registers
    them: the env id is Shimmy's (`dm_control/cheetah-run-v0`) or `<domain>-<task>` for the
    suite (`cheetah-run`). Observations are dm_control's dict of float64 arrays; the episode
    ends as dm_control's time limit says (`truncated`); options go to Shimmy (`task_kwargs`,
    `environment_kwargs`, `render_kwargs`, ...)."""

    name = "dm_control"
    frameworks = ["dm_control", "dmc", "shimmy"]
    requires = ["dm_control", "shimmy", "mujoco"]
    description = "DeepMind Control Suite through Shimmy's Gymnasium ids (MuJoCo 3.17), hosted in a Python worker"
    install_hint = (
        "pip install 'shimmy[dm-control]==2.0.1' dm_control==1.0.50 mujoco==3.17.0 packaging "
        "(the catalog's Python environment `dm_control`; dm_control fails on mujoco 4.0)"
    )
    mujoco_series = ("3.17.",)
    python_env = "dm_control"

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym
        import shimmy  # noqa: F401 - registers the dm_control ids

        if not env_id.startswith(PREFIX) and f"{PREFIX}{env_id}-v0" in gym.registry:
            env_id = f"{PREFIX}{env_id}-v0"
        if env_id not in gym.registry:
            ids = sorted(i for i in gym.registry if i.startswith(PREFIX))
            raise unknown_id(
                "dm_control (through Shimmy)",
                env_id,
                ids,
                "write Shimmy's id (`dm_control/cheetah-run-v0`) or `<domain>-<task>` (`cheetah-run`); "
                f"{len(ids)} ids, e.g. {', '.join(ids[1:6])}",
            )
        return gym_make(env_id, config, dict(config.extra))
