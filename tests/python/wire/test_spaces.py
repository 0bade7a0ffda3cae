"""Spaces from their Rust description to `gymnasium.spaces`, and the flat byte layout of
`Dict`/`Tuple` values split into views (the layout is the one `envhub-core` documents:
children one after another, each on an 8-byte boundary)."""

from __future__ import annotations

import json

import numpy as np
from gymnasium import spaces
from harness import import_envhub

import_envhub()
from envhub.wire.spaces import Codec, to_gymnasium  # noqa: E402

GOAL_DICT = {
    "type": "dict",
    "spaces": [
        ["achieved_goal", {"type": "box", "dtype": "float32", "shape": [3], "low": [-1, -1, -1], "high": [1, 1, 1]}],
        ["observation", {"type": "box", "dtype": "float32", "shape": [5], "low": ["-inf"] * 5, "high": ["inf"] * 5}],
        ["flag", {"type": "discrete", "n": 3, "start": 0}],
    ],
}
GOAL_LEAVES = [
    {"path": '["achieved_goal"]', "offset": 0, "dtype": "float32", "shape": [3], "bytes": 12},
    {"path": '["observation"]', "offset": 16, "dtype": "float32", "shape": [5], "bytes": 20},
    {"path": '["flag"]', "offset": 40, "dtype": "int64", "shape": [], "bytes": 8},
]
TUPLE = {
    "type": "tuple",
    "spaces": [{"type": "discrete", "n": 2, "start": 0}, {"type": "box", "dtype": "float32", "shape": [1], "low": [0], "high": [1]}],
}
TUPLE_LEAVES = [
    {"path": "[0]", "offset": 0, "dtype": "int64", "shape": [], "bytes": 8},
    {"path": "[1]", "offset": 8, "dtype": "float32", "shape": [1], "bytes": 4},
]


def test_every_space_type():
    box = to_gymnasium({"type": "box", "dtype": "float32", "shape": [2], "low": ["-inf", 0], "high": [1, "inf"]})
    assert isinstance(box, spaces.Box) and box.dtype == np.float32
    assert box.low[0] == -np.inf and box.high[1] == np.inf
    assert to_gymnasium({"type": "discrete", "n": 5, "start": -2}) == spaces.Discrete(5, start=-2)
    md = to_gymnasium({"type": "multi_discrete", "nvec": [2, 3], "start": [0, 1]})
    assert md == spaces.MultiDiscrete([2, 3], start=[0, 1])
    assert to_gymnasium({"type": "multi_binary", "shape": [4]}) == spaces.MultiBinary(4)
    d = to_gymnasium(GOAL_DICT)
    assert isinstance(d, spaces.Dict) and set(d.spaces) == {"achieved_goal", "observation", "flag"}
    assert isinstance(to_gymnasium(TUPLE), spaces.Tuple)


def test_dict_observations_are_views_of_the_raw_block():
    codec = Codec(json.dumps(GOAL_DICT), json.dumps(GOAL_LEAVES), json.dumps(TUPLE), json.dumps(TUPLE_LEAVES), 2)
    space = to_gymnasium(GOAL_DICT)
    values = [space.sample() for _ in range(2)]
    raw = np.zeros((2, 48), dtype=np.uint8)
    for i, v in enumerate(values):
        raw[i, 0:12] = v["achieved_goal"].view(np.uint8)
        raw[i, 16:36] = v["observation"].view(np.uint8)
        raw[i, 40:48] = np.int64(v["flag"]).reshape(1).view(np.uint8)
    raw.setflags(write=False)
    obs = codec.obs(raw)
    assert obs["achieved_goal"].shape == (2, 3) and obs["flag"].shape == (2,)
    for i, v in enumerate(values):
        np.testing.assert_array_equal(obs["achieved_goal"][i], v["achieved_goal"])
        np.testing.assert_array_equal(obs["observation"][i], v["observation"])
        assert obs["flag"][i] == v["flag"]
    assert np.shares_memory(obs["observation"], raw) and not obs["observation"].flags.writeable
    single = Codec(json.dumps(GOAL_DICT), json.dumps(GOAL_LEAVES), json.dumps(TUPLE), json.dumps(TUPLE_LEAVES), None)
    one = single.obs_from_bytes(raw[1])
    assert np.shares_memory(one["observation"], raw)
    assert one in space


def test_tuple_actions_are_packed_in_the_layout():
    codec = Codec(json.dumps(GOAL_DICT), json.dumps(GOAL_LEAVES), json.dumps(TUPLE), json.dumps(TUPLE_LEAVES), 3)
    packed = codec.actions((np.array([1, 0, 1]), np.array([[0.5], [0.25], [1.0]], dtype=np.float32)))
    assert packed.shape == (3, 16) and packed.dtype == np.uint8
    np.testing.assert_array_equal(packed[:, 0:8].view(np.int64).ravel(), [1, 0, 1])
    np.testing.assert_array_equal(packed[:, 8:12].view(np.float32).ravel(), [0.5, 0.25, 1.0])
