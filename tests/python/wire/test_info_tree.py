"""`envhub.wire.info_tree`: nested infos (MyoSuite's, Meta-World's episode statistics) through the
data plane's text values, exactly and without pickle. Needs no suite."""

from __future__ import annotations

import enum
import json

import numpy as np
from harness import import_envhub

import_envhub()

from envhub.wire import info_tree as _info_tree  # noqa: E402


class Kind(enum.IntEnum):
    MID = 1


def test_flat_infos_stay_plain():
    info = {"success": 1.0, "steps": 3, "done": False, "task": "reach"}
    assert _info_tree.encode(info) is info
    assert _info_tree.decode(info) is info


def test_nested_infos_round_trip_with_dtypes_and_bytes():
    info = {
        "obs_dict": {"qpos": np.array([0.1, -2.5e-300]), "act": np.arange(6, dtype=np.float32).reshape(2, 3)},
        "rwd_dict": {"solved": np.bool_(True), "dense": -1.4539302, "pose": np.float64(0.25), "n": np.int32(-7)},
        "episode": {"r": 720.23, "l": 500, "t": 0.23},
        "list": [1, (2.0, "x"), None],
        "special": [float("nan"), float("inf"), 2**70],
        "kind": Kind.MID,
    }
    wire = _info_tree.encode(info)
    assert list(wire) == [_info_tree.KEY] and isinstance(wire[_info_tree.KEY], str)
    json.loads(wire[_info_tree.KEY])  # plain JSON text, no pickle
    got = _info_tree.decode(wire)
    assert got["obs_dict"]["qpos"].dtype == np.float64
    assert got["obs_dict"]["qpos"].tobytes() == info["obs_dict"]["qpos"].tobytes()
    assert got["obs_dict"]["act"].dtype == np.float32 and got["obs_dict"]["act"].shape == (2, 3)
    np.testing.assert_array_equal(got["obs_dict"]["act"], info["obs_dict"]["act"])
    assert got["obs_dict"]["act"].flags.writeable
    assert type(got["rwd_dict"]["solved"]) is np.bool_ and got["rwd_dict"]["solved"]
    assert type(got["rwd_dict"]["pose"]) is np.float64 and got["rwd_dict"]["pose"] == 0.25
    assert type(got["rwd_dict"]["n"]) is np.int32 and got["rwd_dict"]["n"] == -7
    assert got["rwd_dict"]["dense"] == -1.4539302 and got["episode"] == info["episode"]
    assert got["list"] == [1, (2.0, "x"), None]
    assert np.isnan(got["special"][0]) and got["special"][1] == float("inf") and got["special"][2] == 2**70
    assert got["kind"] == 1 and type(got["kind"]) is int


def test_other_objects_arrive_as_their_text():
    got = _info_tree.decode(_info_tree.encode({"obj": object()}))
    assert got["obj"].startswith("<object object at")
