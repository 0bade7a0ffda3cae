"""`envhub.AsyncVectorEnv` against `gymnasium.vector.AsyncVectorEnv`: the same factories
(a class of this module, lambdas, a MuJoCo env, a class of a script's `__main__`) give the
same results bit for bit, step for step, over several episodes and autoresets; and the
errors a drop-in can meet (a factory that raises or cannot be pickled, a custom worker)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from harness import import_envhub
from hub_daemons import daemon  # noqa: F401 - the `envhub serve` fixture
from vector_checks import STEP_TIMEOUT, assert_same

envhub = import_envhub()

# Every session of these tests fails instead of hanging on a stuck worker.
class CounterEnv(gym.Env):
    """A custom env defined in the test module: random episode ends (from its seeded
    `np_random`), a time limit, and infos of many kinds (numpy scalars of several dtypes,
    arrays, text, nested dicts) that must arrive exactly as Gymnasium delivers them."""

    metadata = {"render_modes": [], "custom": "counter"}

    def __init__(self, limit: int = 7, gain: float = 1.0) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
        self.action_space = gym.spaces.Discrete(3)
        self.limit, self.gain, self.t = limit, gain, 0
        self.state = np.zeros(3, np.float32)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        start = float((options or {}).get("start", 0.0))
        self.state = (self.np_random.standard_normal(3) + start).astype(np.float32)
        info = {"start": start, "options_seen": options is not None, "noise": self.np_random.random()}
        return self.state.copy(), info

    def scaled(self, k: float, offset: float = 0.0) -> float:
        return self.gain * k + offset

    def step(self, action: Any) -> Any:
        assert self.action_space.contains(action), action
        self.t += 1
        self.state = (self.state * 0.9 + self.gain * (int(action) - 1)).astype(np.float32)
        terminated = bool(self.np_random.random() < 0.08)
        truncated = self.t >= self.limit
        info = {
            "t": self.t,
            "energy": np.float32(np.square(self.state).sum()),
            "small": np.int16(self.t),
            "flag": np.bool_(terminated),
            "label": f"step-{self.t}",
        }
        if self.t % 3 == 0:  # values JSON cannot carry: the whole info travels pickled
            info["counts"] = np.array([self.t, 2 * self.t], np.int16)
            info["nested"] = {"x": float(self.state[0]), "flag": terminated}
        if self.t % 2:
            info["odd"] = np.int64(self.t)  # only some envs report it: its `_odd` mask differs
        return self.state.copy(), float(self.state.sum()), terminated, truncated, info


def _counter_fns(n: int) -> list[Any]:
    return [lambda i=i: CounterEnv(limit=5 + i, gain=0.5 + 0.1 * i) for i in range(n)]


def run_both(env_fns: list[Any], steps: int, seed: int, actions: Any, **kwargs: Any) -> int:
    """Steps envhub's and Gymnasium's AsyncVectorEnv side by side, comparing every result;
    returns how many episodes ended."""
    ours = envhub.AsyncVectorEnv(env_fns, step_timeout=STEP_TIMEOUT, **kwargs)
    ref = gym.vector.AsyncVectorEnv(env_fns, **{k: v for k, v in kwargs.items() if k != "num_workers"})
    try:
        assert ours.single_observation_space == ref.single_observation_space
        assert ours.action_space == ref.action_space
        assert ours.metadata == ref.metadata
        assert ours.render_mode == ref.render_mode
        assert_same(ours.reset(seed=seed), ref.reset(seed=seed), "reset")
        ended = 0
        for t in range(steps):
            a = actions(t)
            got, want = ours.step(a), ref.step(a)
            assert_same(got, want, f"step {t}")
            ended += int(np.sum(want[2] | want[3]))
        return ended
    finally:
        ours.close()
        ref.close()


@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP])
def test_module_class_matches_gymnasium_step_for_step(mode):
    rng = np.random.default_rng(1)
    acts = rng.integers(0, 3, size=(120, 5))
    ended = run_both(_counter_fns(5), 120, 11, lambda t: acts[t], num_workers=2, autoreset_mode=mode)
    assert ended > 20  # several episodes per env, so autoreset is exercised


def test_reset_options_masks_and_seed_lists_match_gymnasium():
    fns = _counter_fns(4)
    ours = envhub.AsyncVectorEnv(fns, num_workers=2, autoreset_mode="Disabled", step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns, autoreset_mode="Disabled")
    try:
        seeds, options = [3, 9, 5, 6], {"start": 2.5}
        assert_same(ours.reset(seed=seeds, options=options), ref.reset(seed=seeds, options=options), "reset")
        for t in range(40):
            a = np.full(4, t % 3)
            got, want = ours.step(a), ref.step(a)
            assert_same(got, want, f"step {t}")
            done = want[2] | want[3]
            if done.any():
                assert_same(
                    ours.reset(options={"reset_mask": done.copy(), "start": float(t)}),
                    ref.reset(options={"reset_mask": done.copy(), "start": float(t)}),
                    f"masked reset at {t}",
                )
    finally:
        ours.close()
        ref.close()


@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP])
def test_lambda_mujoco_env_matches_gymnasium(mode):
    # MuJoCo's infos are numpy float64s and float32s; Box actions drawn from the action space.
    fns = [lambda: gym.make("Hopper-v5") for _ in range(3)]
    space = gym.make("Hopper-v5").action_space
    space.seed(0)
    acts = [np.stack([space.sample() for _ in range(3)]) for _ in range(150)]
    ended = run_both(fns, 150, 0, lambda t: acts[t], autoreset_mode=mode)
    assert ended > 0


def test_rgb_frames_match_gymnasium():
    fns = [lambda: gym.make("CartPole-v1", render_mode="rgb_array") for _ in range(2)]
    ours = envhub.AsyncVectorEnv(fns, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns)
    try:
        assert ours.render_mode == ref.render_mode == "rgb_array"
        ours.reset(seed=1), ref.reset(seed=1)
        ours.step(np.array([0, 1])), ref.step(np.array([0, 1]))
        assert_same(ours.render(), ref.render(), "render")
    finally:
        ours.close()
        ref.close()


def test_step_async_and_wait_as_gymnasium():
    envs = envhub.AsyncVectorEnv(_counter_fns(2), step_timeout=STEP_TIMEOUT)
    try:
        envs.reset(seed=0)
        envs.step_async(np.array([1, 2]))
        with pytest.raises(envhub.InvalidStateError, match="awaits"):
            envs.step_async(np.array([1, 2]))
        obs, *_ = envs.step_wait()
        assert obs.shape == (2, 3)
        with pytest.raises(envhub.InvalidStateError, match="without a prior"):
            envs.step_wait()
    finally:
        envs.close()


def test_call_get_attr_and_set_attr_reach_the_envs_as_in_gymnasium():
    fns = _counter_fns(3)
    ours = envhub.AsyncVectorEnv(fns, num_workers=2, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns)
    try:
        for envs in (ours, ref):
            envs.reset(seed=0)
            envs.set_attr("gain", [0.0, 1.0, 2.0])
            envs.set_attr("label", "same for all")
        assert ours.get_attr("limit") == ref.get_attr("limit") == (5, 6, 7)
        assert ours.get_attr("gain") == ref.get_attr("gain") == (0.0, 1.0, 2.0)
        assert ours.get_attr("label") == ("same for all",) * 3
        assert_same(ours.step(np.array([2, 2, 2])), ref.step(np.array([2, 2, 2])), "step after set_attr")
        assert ours.call("action_space") == ref.call("action_space")
        assert ours.call("scaled", 3.0, offset=1.0) == ref.call("scaled", 3.0, offset=1.0) == (1.0, 4.0, 7.0)
        with pytest.raises(ValueError, match="use `reset` directly"):
            ours.call("reset")
        with pytest.raises(AttributeError):
            ours.get_attr("no_such_attribute")
        ours.send(np.array([0]), [0])
        with pytest.raises(envhub.InvalidStateError, match="await their `recv`"):
            ours.call("limit")
        ours.recv()
        assert ours.call("limit") == (5, 6, 7)  # the channel still works after an error
    finally:
        ours.close()
        ref.close()


MAIN_SCRIPT = textwrap.dedent(
    """\
    import gymnasium as gym
    import numpy as np
    import envhub

    class Walk(gym.Env):  # a class of __main__: cloudpickled by value
        def __init__(self, step_size):
            self.observation_space = gym.spaces.Box(-10, 10, (2,), np.float64)
            self.action_space = gym.spaces.Box(-1, 1, (2,), np.float32)
            self.step_size = step_size
        def reset(self, seed=None, options=None):
            super().reset(seed=seed)
            self.pos = self.np_random.uniform(-1, 1, 2)
            return self.pos.copy(), {"where": self.pos.copy()}
        def step(self, action):
            self.pos = self.pos + self.step_size * action
            done = bool(np.abs(self.pos).max() > 2)
            return self.pos.copy(), -float(np.abs(self.pos).sum()), done, False, {}

    if __name__ == "__main__":
        fns = [lambda k=k: Walk(0.3 + 0.1 * k) for k in range(3)]
        ours, ref = envhub.AsyncVectorEnv(fns, step_timeout=60), gym.vector.AsyncVectorEnv(fns)
        a, b = ours.reset(seed=4), ref.reset(seed=4)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1]["where"], b[1]["where"])
        space = ours.action_space
        space.seed(1)
        dones = 0
        for t in range(100):
            act = space.sample()
            x, y = ours.step(act), ref.step(act)
            for u, v in zip(x[:4], y[:4]):
                assert u.dtype == v.dtype and np.array_equal(u, v), (t, u, v)
            dones += int(y[2].sum())
        ours.close(); ref.close()
        assert dones > 0
        print("main ok", dones)
    """
)


def test_factories_of_a_script_main_match_gymnasium(tmp_path):
    script = tmp_path / "train.py"
    script.write_text(MAIN_SCRIPT)
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=180, cwd=tmp_path
    )
    assert out.returncode == 0 and "main ok" in out.stdout, out.stderr[-3000:]


def _raises_in_worker() -> Any:
    if os.environ.get("ENVHUB_DROPIN_PARENT") == str(os.getpid()):
        return CounterEnv()  # the parent builds env 0 once, as Gymnasium does
    raise RuntimeError("boom: no simulator licence")


def test_a_factory_that_raises_is_reported_with_its_error(monkeypatch):
    monkeypatch.setenv("ENVHUB_DROPIN_PARENT", str(os.getpid()))
    with pytest.raises(envhub.MakeError, match=r"(?s)env factory 1 .*boom: no simulator licence"):
        envhub.AsyncVectorEnv([CounterEnv, _raises_in_worker], step_timeout=STEP_TIMEOUT)
    # Factory 0 runs in this process first, so its error is the factory's own, as in Gymnasium.
    with pytest.raises(ZeroDivisionError):
        envhub.AsyncVectorEnv([lambda: 1 / 0], step_timeout=STEP_TIMEOUT)


def test_an_unpicklable_factory_is_named():
    lock = threading.Lock()

    def holds_lock() -> Any:
        with lock:
            return CounterEnv()

    with pytest.raises(envhub.InvalidConfigError, match=r"(?s)env factory 1 .*holds_lock.*cannot be pickled.*hint"):
        envhub.AsyncVectorEnv([CounterEnv, holds_lock])


def test_options_that_cannot_apply_are_refused():
    with pytest.raises(envhub.InvalidConfigError, match="custom Gymnasium worker"):
        envhub.AsyncVectorEnv([CounterEnv], worker=lambda *a: None)
    with pytest.raises(ValueError):
        envhub.AsyncVectorEnv([CounterEnv], context="no-such-context")
    with pytest.raises(envhub.InvalidConfigError, match="empty"):
        envhub.AsyncVectorEnv([])


@pytest.fixture
def short_tmp_path() -> Iterator[Path]:
    """A temporary folder with a short path: the workers' call sockets go in a folder inside
    it, and a Unix socket's path has at most 107 bytes, which a pytest-xdist `tmp_path`
    (`/tmp/pytest-of-USER/pytest-N/popen-gwN/test_...0/`) leaves no room for."""
    folder = Path(tempfile.mkdtemp(prefix="eh-", dir="/tmp"))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_temporary_files_are_removed(short_tmp_path, monkeypatch):
    tmp_path = short_tmp_path
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # this test's own temporary folder
    envs = envhub.AsyncVectorEnv(
        _counter_fns(2), shared_memory=False, copy=False, daemon=False, step_timeout=STEP_TIMEOUT
    )
    try:
        # The factories' file is gone once the workers are up; the call sockets stay.
        assert [p.name.startswith("envhub-calls-") for p in tmp_path.iterdir()] == [True]
        envs.reset(seed=0)
    finally:
        envs.close()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(envhub.MakeError):
        envhub.AsyncVectorEnv([CounterEnv, _raises_in_worker], step_timeout=STEP_TIMEOUT)
    lock = threading.Lock()
    with pytest.raises(envhub.InvalidConfigError):
        envhub.AsyncVectorEnv([CounterEnv, lambda: (lock, CounterEnv())[1]])
    assert list(tmp_path.iterdir()) == []


def test_through_a_hub_daemon(daemon):
    # The daemon's workers load the factories from the same temporary file.
    assert os.environ.get("ENVHUB_HUB")
    rng = np.random.default_rng(2)
    acts = rng.integers(0, 3, size=(60, 3))
    assert run_both(_counter_fns(3), 60, 4, lambda t: acts[t], num_workers=2) > 5
