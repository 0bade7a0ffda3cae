"""LeRobot's observation layout for a catalog entry that has no LeRobot env of its own: camera
images under `pixels` (`observation.images.<name>` after LeRobot's `preprocess_observation`,
or `observation.image` for an image-only entry) and every other value, flattened in key order,
as `agent_pos` (`observation.state`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


def is_image(space: Any) -> bool:
    return (
        isinstance(space, gym.spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and space.shape[-1] in (1, 3)
    )


def _leaves(space: Any, prefix: str = "") -> list[tuple[str, Any]]:
    if isinstance(space, gym.spaces.Dict):
        out: list[tuple[str, Any]] = []
        for key, sub in space.spaces.items():
            out += _leaves(sub, f"{prefix}{key}" if not prefix else f"{prefix}.{key}")
        return out
    if isinstance(space, gym.spaces.Box):
        return [(prefix, space)]
    raise TypeError(
        f"the observation part `{prefix or '(whole)'}` is a {type(space).__name__}; LeRobot's plugin maps Box "
        "and Dict observations (images and states)"
    )


class Converter:
    """Maps an entry's observations (from its space) to LeRobot's layout."""

    def __init__(self, space: Any) -> None:
        self.source = space
        leaves = _leaves(space)
        self.images = [(k, s) for k, s in leaves if is_image(s)]
        self.states = [(k, s) for k, s in leaves if not is_image(s)]
        self.state_dim = int(sum(int(np.prod(s.shape)) for _, s in self.states))
        # An image-only Box is LeRobot's single `pixels` array (observation.image).
        self.single_image = len(leaves) == 1 and bool(self.images) and leaves[0][0] == ""

    def features(self) -> tuple[dict[str, Any], dict[str, str]]:
        """LeRobot's `features` (PolicyFeature per env key) and `features_map`."""
        from lerobot.configs import FeatureType, PolicyFeature
        from lerobot.utils.constants import ACTION, OBS_IMAGE, OBS_IMAGES, OBS_STATE

        features: dict[str, Any] = {}
        mapping: dict[str, str] = {ACTION: ACTION}
        for key, space in self.images:
            name = "pixels" if self.single_image else f"pixels/{key}"
            features[name] = PolicyFeature(type=FeatureType.VISUAL, shape=tuple(space.shape))
            mapping[name] = OBS_IMAGE if self.single_image else f"{OBS_IMAGES}.{key}"
        if self.states:
            features["agent_pos"] = PolicyFeature(type=FeatureType.STATE, shape=(self.state_dim,))
            mapping["agent_pos"] = OBS_STATE
        return features, mapping

    def space(self, _: Any = None) -> Any:
        out: dict[str, Any] = {}
        if self.single_image:
            out["pixels"] = self.images[0][1]
        elif self.images:
            out["pixels"] = gym.spaces.Dict(dict(self.images))
        if self.states:
            out["agent_pos"] = gym.spaces.Box(-np.inf, np.inf, (self.state_dim,), np.float64)
        return gym.spaces.Dict(out)

    def __call__(self, obs: Any) -> dict[str, Any]:
        def leaf(key: str) -> Any:
            value = obs
            for part in key.split(".") if key else []:
                value = value[part]
            return np.asarray(value)

        out: dict[str, Any] = {}
        if self.single_image:
            out["pixels"] = leaf("")
        elif self.images:
            out["pixels"] = {k: leaf(k) for k, _ in self.images}
        if self.states:
            parts = [leaf(k) for k, _ in self.states]
            n = parts[0].shape[0]
            out["agent_pos"] = np.concatenate([p.reshape(n, -1).astype(np.float64) for p in parts], axis=1)
        return out
