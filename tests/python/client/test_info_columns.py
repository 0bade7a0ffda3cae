"""Typed info columns (`envhub.wire.info_schema`, `envhub.client.column_reader`, `envhub.worker.column_writer`): the drop-in's numeric infos travel as typed
columns of the batch slot and reach the caller as views of it, still exactly what
Gymnasium's `AsyncVectorEnv` delivers (dtypes, key order, masks) in every autoreset mode;
infos outside the learned schema (text, nested dicts, new keys, other dtypes) take the
exact JSON path for that env and step; a schema that does not fit its row is refused."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from harness import import_envhub
from vector_checks import STEP_TIMEOUT, assert_same

envhub = import_envhub()
from envhub import _envhub  # noqa: E402
from envhub.client.column_reader import ColumnReader  # noqa: E402
from envhub.worker.column_writer import ColumnWriter  # noqa: E402

MODES = [gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP, gym.vector.AutoresetMode.DISABLED]


class NumericEnv(gym.Env):
    """Infos of every dtype a column holds: Python scalars, numpy scalars (including uint64
    past 2**63 and float16), arrays, a key only some steps report, and a reset info whose
    keys are a prefix of the step's."""

    metadata = {"render_modes": []}

    def __init__(self, limit: int = 9) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.limit, self.t = limit, 0
        self.x = np.zeros(2)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        self.x = self.np_random.standard_normal(2)
        return self.x.copy(), {"start": float(self.x[0]), "seed_bits": np.uint64(2**63 + 5)}

    def step(self, action: Any) -> Any:
        self.t += 1
        self.x = self.x * 0.5 + action
        info: dict[str, Any] = {
            "start": float(self.x[0]),
            "seed_bits": np.uint64(2**63 + self.t),
            "t": self.t,
            "ok": self.t % 4 != 0,
            "energy": np.float32(np.square(self.x).sum()),
            "small": np.int16(-self.t),
            "half": np.float16(self.t / 3),
            "pair": self.x.astype(np.float32),
            "hits": np.array([self.t % 2 == 0, True]),
        }
        if self.t % 2:
            info["odd"] = np.int32(self.t)  # only some steps, so only some envs: `_odd` varies
        terminated = bool(self.np_random.random() < 0.1)
        return self.x.copy(), float(self.x.sum()), terminated, self.t >= self.limit, info


class MixedEnv(NumericEnv):
    """Mostly numeric infos, now and then one the schema cannot hold: text, a nested dict, a
    new key, a value of another type, a `np.bool_` (an object array in Gymnasium)."""

    def __init__(self, limit: int = 9, twist: int = 0) -> None:
        super().__init__(limit)
        self.twist = twist

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = super().step(action)
        k = (self.t + self.twist) % 6
        if k == 1:
            info["label"] = f"t{self.t}"
        elif k == 2:
            info["nested"] = {"x": float(obs[0]), "deep": {"n": self.t}}
        elif k == 3:
            info["start"] = np.float32(info["start"])  # same key, another dtype
        elif k == 4:
            info["flag"] = np.bool_(terminated)
        if self.twist == 1:
            info["t"] = float(info["t"])  # env 1's `t` is a float: Gymnasium keeps env 0's dtype
        return obs, reward, terminated, truncated, info


def _in_slot(array: Any) -> bool:
    """Whether `array` views a shared-memory batch slot (its bases reach the slot's owner)."""
    while array is not None:
        if type(array).__name__ == "SharedSlot":
            return True
        array = getattr(array, "base", None)
    return False


def _step_both(ours: Any, ref: Any, steps: int, seed: int, mode: Any) -> tuple[int, int]:
    """Steps both side by side, comparing every result; returns how many steps had every
    info array in the slot, and how many had some info that was not."""
    rng = np.random.default_rng(seed)
    assert_same(ours.reset(seed=seed), ref.reset(seed=seed), "reset")
    viewed = copied = 0
    for t in range(steps):
        a = rng.uniform(-1, 1, ours.action_space.shape).astype(np.float32)
        got, want = ours.step(a), ref.step(a)
        assert_same(got, want, f"step {t}")
        arrays = [v for v in got[4].values() if isinstance(v, np.ndarray)]
        if arrays and all(_in_slot(v) for v in arrays):
            viewed += 1
        elif arrays:
            copied += 1
        if mode == gym.vector.AutoresetMode.DISABLED:
            done = want[2] | want[3]
            if done.any():
                assert_same(
                    ours.reset(options={"reset_mask": done}), ref.reset(options={"reset_mask": done}), f"reset {t}"
                )
    return viewed, copied


@pytest.mark.parametrize("mode", MODES)
def test_numeric_infos_are_views_of_the_slot_and_match_gymnasium(mode):
    fns = [lambda i=i: NumericEnv(limit=6 + i) for i in range(4)]
    ours = envhub.AsyncVectorEnv(fns, num_workers=2, autoreset_mode=mode, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns, autoreset_mode=mode)
    try:
        viewed, _ = _step_both(ours, ref, 60, 3, mode)
    finally:
        ours.close()
        ref.close()
    # Steps where no episode ended (same_step's final infos go the exact way) are views.
    assert viewed >= 20, viewed


@pytest.mark.parametrize("mode", MODES)
def test_infos_outside_the_schema_take_the_exact_path_for_that_step(mode):
    fns = [lambda i=i: MixedEnv(limit=7 + i, twist=i) for i in range(3)]
    ours = envhub.AsyncVectorEnv(fns, num_workers=2, autoreset_mode=mode, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns, autoreset_mode=mode)
    try:
        _, copied = _step_both(ours, ref, 60, 5, mode)
    finally:
        ours.close()
        ref.close()
    assert copied > 0


def test_one_env_per_worker_and_send_recv_keep_the_columns_exact():
    fns = [lambda i=i: NumericEnv(limit=5 + i) for i in range(4)]
    ours = envhub.AsyncVectorEnv(fns, num_workers=4, step_timeout=STEP_TIMEOUT)
    ref = [fn() for fn in fns]
    try:
        ours.reset(seed=7)
        for i, env in enumerate(ref):
            env.reset(seed=7 + i)
        batch = type("B", (), {"_add_info": gym.vector.VectorEnv._add_info})
        pending: dict[int, np.ndarray] = {}
        resetting: set[int] = set()
        rng = np.random.default_rng(0)
        for _ in range(30):
            ids = [i for i in range(4) if i not in pending and rng.random() < 0.7]
            if ids:
                acts = rng.uniform(-1, 1, (len(ids), 2)).astype(np.float32)
                ours.send(acts, ids)
                pending.update({i: acts[k] for k, i in enumerate(ids)})
            if not pending:
                continue
            _, _, _, _, info = ours.recv()
            got_ids = [int(i) for i in info.pop("env_id")]
            want: dict[str, Any] = {}
            b = batch()
            b.num_envs = len(got_ids)
            for k, i in enumerate(got_ids):
                act = pending.pop(i)
                if i in resetting:  # next_step: the step after an episode's end only resets
                    resetting.discard(i)
                    env_info = ref[i].reset()[1]
                else:
                    _, _, term, trunc, env_info = ref[i].step(act)
                    if term or trunc:
                        resetting.add(i)
                want = b._add_info(want, env_info, k)
            assert_same(info, want, f"recv {got_ids}")
    finally:
        ours.close()


def test_a_schema_that_does_not_fit_its_row_is_refused():
    ok = '{"id": 5, "keys": [{"key": "x", "dtype": "<f8", "shape": [], "offset": 8, "mask": 16, "kind": "py"}]}'
    sid, columns = _envhub.info_schema(ok, 24)
    assert sid == 5 and columns == [("x", "<f8", [], 8, 16, "py")]
    with pytest.raises(ValueError, match="past a row of 16 bytes"):
        _envhub.info_schema(ok, 16)
    for bad, why in [
        (ok.replace('"offset": 8', '"offset": 12'), "not aligned"),
        (ok.replace('"mask": 16', '"mask": 9'), "overlap"),
        (ok.replace('"<f8"', '"|O"'), "not a column dtype"),
        (ok.replace('"shape": []', '"shape": [4611686018427387904, 4]').replace('"py"', '"array"'), "does not fit"),
        (ok.replace('"id": 5', '"id": 0'), "id 0"),
        ("[1, 2]", "not a schema"),
    ]:
        with pytest.raises(ValueError, match=why):
            _envhub.info_schema(bad, 64)
    reader = ColumnReader(64)
    with pytest.raises(ValueError, match="not aligned"):
        reader.learn([{"__envhub_schema__": ok.replace('"offset": 8', '"offset": 12')}])
    cols = np.zeros((2, 64), np.uint8)
    cols[:, :8] = np.frombuffer(np.uint64(77).tobytes(), np.uint8)
    with pytest.raises(ValueError, match="no worker announced"):
        reader.columns(cols, 77)


def test_the_writer_declines_what_gymnasium_would_not_batch_as_it():
    writer = ColumnWriter(64)
    rows = memoryview(bytearray(2 * 64))
    assert writer.write(rows, 0, {"x": 1.5, "n": 3}) not in (False, None)  # a new schema, announced
    assert writer.write(rows, 1, {"x": 2.5}) is None  # a prefix of it: same schema, known
    assert writer.write(rows, 0, {"n": 2**64}) is False  # beyond int64
    assert writer.write(rows, 0, {"x": np.bool_(True)}) is False  # an object array in Gymnasium
    assert writer.write(rows, 0, {"x": "text"}) is False
    assert writer.write(rows, 0, {"_x": 1.0}) is False  # would collide with a mask's name
    assert writer.write(rows, 0, {"big": np.zeros(100)}) is False  # does not fit the row
    assert rows[:8].tobytes() == bytes(8)  # a declined row says so: its info goes as JSON


def test_keys_the_session_adds_to_a_row_s_info_are_kept():
    # A restarted worker's envs get `worker_restarted` from the session as JSON, beside the
    # row their info was written in: the env's dict is the row's values, then those keys.
    writer = ColumnWriter(64)
    rows = memoryview(bytearray(2 * 64))
    text = writer.write(rows, 0, {"x": 1.5, "n": np.int16(3)})
    assert writer.write(rows, 1, {"x": 2.5, "n": np.int16(4)}) is None
    client = envhub.AsyncVectorEnv.__new__(envhub.AsyncVectorEnv)
    client._columns = ColumnReader(64)
    infos = client._columns.learn([{"__envhub_schema__": text}, {"worker_restarted": True}])
    got = client._info(infos, None, 2, np.frombuffer(rows, np.uint8).reshape(2, 64))
    batch = type("B", (), {"_add_info": gym.vector.VectorEnv._add_info, "num_envs": 2})()
    want = batch._add_info({}, {"x": 1.5, "n": np.int16(3)}, 0)
    want = batch._add_info(want, {"x": 2.5, "n": np.int16(4), "worker_restarted": True}, 1)
    assert_same(got, want, "merged")
