"""How many worker processes a lock-step batch of a suite's envs should get."""

from __future__ import annotations

import math

#: How far above the ideal (every core busy until the batch's last env is stepped) a worker
#: count's batch time may be before one more worker is worth its process.
SLACK = 1.1


def balanced_workers(envs: int, cores: float) -> int:
    """The fewest workers (at least one per core, at most one per env) whose batch time is
    within `SLACK` of the ideal, for envs of equal step cost on `cores` cores.

    LeRobot's rollout steps its batch in lock step, and a worker steps its envs one after the
    other, so a batch takes as long as the largest share: 5 envs on 2 workers are stepped in 3
    env-steps' time where 2 cores allow 2.5; 3 workers (2, 2, 1) share the 2 cores in 2.5.
    For envs whose step is costly (a suite's physics and rendering): where a step takes
    microseconds, a wake-up costs more than the imbalance.
    """
    if envs < 1:
        raise ValueError(f"a batch needs at least one env; got {envs}")
    if cores <= 0:
        raise ValueError(f"cores must be positive; got {cores}")
    ideal = max(1.0, envs / cores)  # a batch takes at least one env-step's time
    for workers in range(max(1, min(envs, math.floor(cores))), envs + 1):
        if math.ceil(envs / workers) <= SLACK * ideal:
            return workers
    return envs
