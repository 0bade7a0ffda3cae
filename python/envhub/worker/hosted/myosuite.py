"""`myosuite`: MyoSuite's musculoskeletal tasks (MyoHand, MyoElbow, MyoLeg, challenges) as
MyoSuite registers them in Gymnasium."""

from __future__ import annotations

from typing import Any

from .suites import SuiteAdapter, gym_make, unknown_id


class MyoSuiteAdapter(SuiteAdapter):
    """MyoSuite tasks by their Gymnasium id (`myoElbowPose1D6MRandom-v0`,
    `myoHandReachFixed-v0`, ...); options go to `gymnasium.make`. MyoSuite's infos (nested
    dicts of numpy arrays and scalars: `obs_dict`, `rwd_dict`, ...) arrive whole, with their
    dtypes."""

    name = "myosuite"
    frameworks = ["myosuite"]
    requires = ["myosuite", "mujoco"]
    description = "MyoSuite musculoskeletal tasks (MuJoCo 4.0), hosted in a Python worker"
    install_hint = "pip install myosuite==3.0.0 (the catalog's Python environment `myosuite`; it needs gymnasium<1.3)"
    mujoco_series = ("4.0.",)
    python_env = "myosuite"

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym
        import myosuite  # noqa: F401 - registers the ids

        if env_id not in gym.registry:
            ids = sorted(i for i in gym.registry if i.startswith("myo"))
            raise unknown_id("MyoSuite", env_id, ids, f"MyoSuite registers {len(ids)} ids, e.g. {', '.join(ids[:5])}")
        return gym_make(env_id, config, dict(config.extra))
