"""Scripted experts, as batched policies: `metaworld` plays Meta-World's own scripted policy
of each task (`metaworld.policies.ENV_POLICY_MAP`; needs `metaworld` importable: run it with
`--policy-env metaworld`). Actions in the action space's dtype (float32), as a Gymnasium agent
returns them."""

from __future__ import annotations

from typing import Any

import numpy as np

from .callable import PerTask
from .policy import Task


class _MetaWorldExpert:
    def __init__(self, task: Task) -> None:
        from metaworld.policies import ENV_POLICY_MAP

        name = task.id.rsplit("/", 1)[-1]
        if name not in ENV_POLICY_MAP:
            name = task.text
        if name not in ENV_POLICY_MAP:
            from .benchmarks import closest

            raise closest(name, sorted(ENV_POLICY_MAP), "Meta-World task for a scripted policy")
        self.policy = ENV_POLICY_MAP[name]()

    def get_action(self, obs: Any) -> np.ndarray:
        return np.asarray(self.policy.get_action(np.asarray(obs)), dtype=np.float32)


metaworld = PerTask(_MetaWorldExpert)
