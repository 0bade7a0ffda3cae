"""Episode limits: the Gymnasium specs of envhub's ids carry the catalog's limits (Gymnasium's,
Gymnasium-Robotics', the Rapier tasks'), every catalog entry but LIBERO, Isaac Lab and
ManiSkill has one, and `gymnasium.make` truncates once, where Gymnasium does."""

from __future__ import annotations

import gymnasium
import pytest
from harness import import_envhub

envhub = import_envhub()

REGISTRY = envhub.EnvRegistry()


def test_gymnasium_specs_carry_the_episode_limit():
    spec, ref = gymnasium.spec("envhub/gym-cartpole"), gymnasium.spec("CartPole-v1")
    assert spec.max_episode_steps == ref.max_episode_steps == 500
    assert spec.reward_threshold == ref.reward_threshold
    assert spec.nondeterministic == ref.nondeterministic


RAPIER_LIMITS = {"rapier-arm-reach": 50, "rapier-arm-push": 100, "rapier-ant-run": 1000, "rapier-rover-terrain": 500}


@pytest.mark.parametrize(("entry_id", "limit"), RAPIER_LIMITS.items())
def test_gymnasium_specs_carry_the_rapier_tasks_limits(entry_id, limit):
    """The registry's limit for a rapier task is the adapter's own (the worker reports it),
    and the Gymnasium spec carries it."""
    assert gymnasium.spec(f"envhub/{entry_id}").max_episode_steps == limit
    env = envhub.make(entry_id, max_episode_steps=0)  # 0: the env's own default, as the worker has it
    try:
        assert env.max_episode_steps == limit
    finally:
        env.close()


ROBOTICS_IDS = [
    ("fetch-reach", "FetchReach-v4"),
    ("hand-manipulate-pen", "HandManipulatePen-v1"),
    ("adroit-door", "AdroitHandDoor-v1"),
    ("point-maze-medium", "PointMaze_Medium-v3"),
    ("ant-maze-umaze", "AntMaze_UMaze-v5"),
    ("franka-kitchen", "FrankaKitchen-v1"),
]


@pytest.mark.parametrize(("entry_id", "gym_id"), ROBOTICS_IDS)
def test_gymnasium_specs_carry_gymnasium_robotics_limits(entry_id, gym_id):
    """Gymnasium-Robotics ids are not in Gymnasium's registry when `envhub` registers its ids;
    their entries carry the limits Gymnasium-Robotics registers."""
    spec = gymnasium.spec(f"envhub/{entry_id}")
    assert spec.max_episode_steps is not None
    robotics = pytest.importorskip("gymnasium_robotics")
    gymnasium.register_envs(robotics)
    assert spec.max_episode_steps == gymnasium.spec(gym_id).max_episode_steps


def test_every_catalog_spec_has_a_limit_but_libero_isaac_and_maniskill():
    """Only frameworks whose limits envhub cannot know without their packages (and that the
    entries do not state) leave `max_episode_steps` out of the spec: ManiSkill, Isaac Lab and
    the suites that run in Python environments of their own (their own limits apply)."""
    unlimited = sorted(
        e.id for e in envhub.EnvRegistry() if gymnasium.spec(f"envhub/{e.id}").max_episode_steps is None
    )
    frameworks = {envhub.EnvRegistry().get(i).framework for i in unlimited}
    assert frameworks <= {"maniskill", "isaac_lab", "metaworld", "robosuite", "dm_control", "myosuite"}, unlimited


def _truncation_step(env, steps=600):
    """The step (1-based) at which an episode of `env` truncates, pushing the pole upright
    so that it does not terminate first; None if it does not within `steps`."""
    obs, _ = env.reset(seed=3)
    for t in range(1, steps + 1):
        obs, _, terminated, truncated, _ = env.step(int(obs[2] + obs[3] > 0))
        assert not terminated, f"terminated at step {t}"
        if truncated:
            return t
    return None


@pytest.mark.parametrize(("limit", "want"), [(None, 500), (7, 7), (550, 550)])
def test_gymnasium_make_truncates_once_where_gymnasium_does(limit, want):
    """`gymnasium.make` wraps the env in `TimeLimit` (the spec's 500, or the caller's); the
    worker then applies no limit of its own, so the episode truncates where Gymnasium's
    CartPole-v1 does, even past the worker's default."""
    kwargs = {} if limit is None else {"max_episode_steps": limit}
    ref = gymnasium.make("CartPole-v1", **kwargs)
    env = gymnasium.make("envhub/gym-cartpole", **kwargs)
    try:
        assert _truncation_step(ref) == want
        assert _truncation_step(env) == want
    finally:
        env.close()
    venv = gymnasium.make_vec("envhub/gym-cartpole", num_envs=2)
    try:
        assert venv.max_episode_steps == 500
    finally:
        venv.close()
