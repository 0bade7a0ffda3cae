"""envhub's environments under LeRobot's own commands: `lerobot-eval --env.type=envhub
--env.task=libero_spatial` (or `metaworld-mt10`, `mujoco-hopper`, any catalog entry or
benchmark). LeRobot imports installed `lerobot_env_*` distributions at start; importing this
one registers `envhub` among LeRobot's env types. The suites run in envhub's own Python
environments, not in LeRobot's interpreter."""

from .config import EnvhubEnv

__all__ = ["EnvhubEnv"]
__version__ = "0.1.0"
