"""The one-pass batching of infos (`envhub.client.infos.flat_infos`) against Gymnasium's own
`VectorEnv._add_info` (and `envhub.client.vector._add_info`, for infos that came as JSON): same keys in the same order, same dtypes, shapes,
values and masks, for every kind of info value it takes; and it declines (None) where
Gymnasium's recursion or special cases apply."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from envhub.client.infos import flat_infos as _flat_infos
from envhub.client.vector import _add_info


class _Batch:
    _add_info = gym.vector.VectorEnv._add_info

    def __init__(self, n: int) -> None:
        self.num_envs = n


def gymnasium_infos(infos: list[dict[str, Any] | None], n: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, info in enumerate(infos):
        if info:
            out = _Batch(n)._add_info(out, info, k)
    return out


def assert_identical(got: dict[str, Any], want: dict[str, Any]) -> None:
    assert list(got) == list(want)
    for key in want:
        a, b = got[key], want[key]
        assert a.dtype == b.dtype and a.shape == b.shape, key
        if b.dtype == object:
            assert [type(x) for x in a] == [type(x) for x in b], key
            assert list(a) == list(b), key
        else:
            assert a.tobytes() == b.tobytes(), key


def _random_info(rng: np.random.Generator) -> dict[str, Any] | None:
    pool: dict[str, Any] = {
        "x_position": np.float64(rng.normal()),
        "reward_ctrl": np.float32(rng.normal()),
        "reward_survive": 1.0,
        "t": int(rng.integers(0, 1000)),
        "small": np.int16(rng.integers(-5, 5)),
        "flag": np.bool_(rng.random() < 0.5),
        "done": bool(rng.random() < 0.5),
        "label": f"step-{rng.integers(9)}",
        "vec": rng.normal(size=3).astype(np.float32),
        "big": np.uint64(2**63 + int(rng.integers(9))),
    }
    keys = [k for k in pool if rng.random() < 0.7]  # sometimes-present keys
    return {k: pool[k] for k in keys} or None


@pytest.mark.parametrize("seed", range(20))
def test_flat_infos_are_gymnasiums(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9))
    infos = [_random_info(rng) for _ in range(n)]
    got = _flat_infos(infos, n)
    assert got is not None
    assert_identical(got, gymnasium_infos(infos, n))


def test_no_info_is_an_empty_dict():
    assert _flat_infos([None, {}, None], 3) == {}


@pytest.mark.parametrize(
    "info",
    [
        {"nested": {"x": 1.0}},  # Gymnasium recurses
        {"final_obs": 1.0},  # Gymnasium batches it as an object array
        {"_x": 1, "x": 2.0},  # a key that is another key's mask
        {1: 2.0},  # not a text key
        {"goal": [1.0, 2.0]},  # a list (envhub.VectorEnv batches it as an array, Gymnasium as objects)
    ],
)
def test_declines_what_gymnasium_treats_apart(info):
    assert _flat_infos([{"a": 1.0}, info], 2) is None


def _json_info(rng: np.random.Generator) -> dict[str, Any] | None:
    pool: dict[str, Any] = {
        "x": float(rng.normal()),
        "t": int(rng.integers(0, 1000)),
        "done": bool(rng.random() < 0.5),
        "label": f"step-{rng.integers(9)}",
    }
    return {k: v for k, v in pool.items() if rng.random() < 0.7} or None


@pytest.mark.parametrize("seed", range(10))
def test_flat_infos_of_json_values_are_make_vecs(seed):
    # What `envhub.make_vec`'s workers send: JSON numbers, flags and text.
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9))
    infos = [_json_info(rng) for _ in range(n)]
    want: dict[str, Any] = {}
    for k, info in enumerate(infos):
        if info:
            want = _add_info(want, info, k, n)
    got = _flat_infos(infos, n)
    assert got is not None
    assert_identical(got, want)
    assert_identical(got, gymnasium_infos(infos, n))


@pytest.mark.parametrize(
    "infos",
    [
        [{"names": ["a", "bb"]}, {"names": ["a", "much longer"]}],  # text lists: never truncated
        [{"ragged": [1, 2, 3]}, {"ragged": [1]}],  # lists of different lengths: no crash
        [{"flag": np.bool_(True)}, {"flag": np.bool_(False)}],  # an object array in Gymnasium
        [{"label": "x"}, None, {"label": "a longer label"}],
        [{"pair": (1, 2)}, {"pair": (3, 4)}],
    ],
)
def test_values_as_json_are_batched_as_gymnasium_batches_them(infos):
    n = len(infos)
    got: dict[str, Any] = {}
    for k, info in enumerate(infos):
        if info:
            got = _add_info(got, info, k, n)
    assert_identical(got, gymnasium_infos(infos, n))
