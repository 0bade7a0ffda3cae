"""`AdapterRegistry().register` of an adapter class defined in the running script
(`__main__`): workers cannot import it by path, so it reaches them cloudpickled. Tested with
a real script run as `__main__`, on the embedded hub and through a hub daemon."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from harness import import_envhub
from hub_daemons import daemon  # noqa: F401 - the `envhub serve` fixture

envhub = import_envhub()

SCRIPT = textwrap.dedent(
    """\
    import os, sys
    import gymnasium as gym
    import numpy as np
    import envhub

    class Ramp(gym.Env):
        def __init__(self, gain):
            self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
            self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
            self.gain, self.t = gain, 0
        def reset(self, seed=None, options=None):
            super().reset(seed=seed)
            self.t = 0
            return np.zeros(2, np.float32), {"who": "main", "pid": os.getpid()}
        def step(self, action):
            self.t += 1
            return np.array([self.t, self.gain * action[0]], np.float32), 0.0, False, False, {}

    class MainSim(envhub.EnvAdapter):
        name = "mainsim"
        frameworks = [os.environ["MAIN_FRAMEWORK"]]
        requires = ["numpy"]
        description = "an adapter of a script's __main__"
        def make(self, env_id, config):
            return Ramp(float(config.extra.get("gain", 1.0)))

    if __name__ == "__main__":
        envhub.AdapterRegistry().register(MainSim)
        assert envhub.AdapterRegistry().get("mainsim")["available"]
        env = envhub.make(sys.argv[1], registry=sys.argv[2] if len(sys.argv) > 2 else None, step_timeout=60)
        obs, info = env.reset(seed=0)
        assert info["who"] == "main" and info["pid"] != os.getpid(), info
        obs, *_ = env.step(np.array([0.5], np.float32))
        assert obs.tolist() == [1.0, 1.0], obs  # gain 2 from the entry's kwargs
        env.close()
        pickled = [p for p in os.environ["ENVHUB_ADAPTERS"].split(",") if p.startswith("pickle:")]
        print("ok", pickled[0][len("pickle:"):])
    """
)

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: main-ramp
        name: A ramp from __main__
        framework: mainsim
        env_id: Ramp-v0
        robot_type: custom
        env_type: floor
        kwargs: {gain: 2}
    """
)


def run_script(tmp_path: Path, framework: str, *args: str) -> str:
    script = tmp_path / "train.py"
    script.write_text(SCRIPT)
    env = {k: v for k, v in os.environ.items() if k != "ENVHUB_ADAPTERS"}
    env["MAIN_FRAMEWORK"] = framework
    out = subprocess.run(
        [sys.executable, str(script), *args], capture_output=True, text=True, timeout=180, cwd=tmp_path, env=env
    )
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr[-3000:]
    pickled = out.stdout.split("ok", 1)[1].strip()
    assert not os.path.exists(pickled), f"{pickled} outlived the script"
    return pickled


def test_adapter_class_of_main_runs_in_an_embedded_hubs_worker(tmp_path):
    registry = tmp_path / "registry.yaml"
    registry.write_text(REGISTRY)
    run_script(tmp_path, "mainsim", "main-ramp", str(registry))


def test_adapter_class_of_a_function_is_pickled_too():
    class Local(envhub.EnvAdapter):
        name = "local_sim_for_test"
        frameworks = ["local_sim_for_test"]

    reg = envhub.AdapterRegistry()
    saved = os.environ.get("ENVHUB_ADAPTERS")
    try:
        reg.register(Local)
        entry = [p for p in os.environ["ENVHUB_ADAPTERS"].split(",") if "Local" in p][0]
        assert entry.startswith("pickle:") and os.path.isfile(entry[len("pickle:") :])
        assert reg.get("local_sim_for_test")["available"]
    finally:
        if saved is None:
            os.environ.pop("ENVHUB_ADAPTERS", None)
        else:
            os.environ["ENVHUB_ADAPTERS"] = saved
        envhub._envhub.refresh_adapters()


def test_unpicklable_adapter_class_is_refused_with_a_hint():
    import threading

    lock = threading.Lock()

    class Holds(envhub.EnvAdapter):
        name = "holds_lock"
        frameworks = ["holds_lock"]
        guard = lock

    with pytest.raises(TypeError, match=r"(?s)cannot be pickled.*hint: move the class into a module"):
        envhub.AdapterRegistry().register(Holds)


def test_adapter_class_of_main_runs_in_a_daemons_worker(daemon):
    # The daemon (started without it) serves `mysim-echo` (framework `mysim`, gain 2).
    assert os.environ.get("ENVHUB_HUB")
    run_script(Path(daemon.args[-1]).parent, "mysim", "mysim-echo")
