"""The worker's cache of compiled MuJoCo models (`envhub.worker.hosted.compiled_models`), which
robosuite's and LIBERO's hard resets go through: a model handed out from it is the model a
compile gives, byte for byte, and the cache keeps only what repeats, within its bound. (The
suites' own runs through it are compared with the suites in-process in pyenv/test_suites.py.)"""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the dev venv's mujoco wheel (requirements-dev.txt) is missing")

from envhub.worker.hosted.compiled_models import CompiledModels  # noqa: E402


def scene(size: float) -> str:
    return (
        "<mujoco><asset><texture name='t' type='2d' builtin='checker' width='64' height='64'/>"
        "<material name='m' texture='t'/></asset><worldbody>"
        f"<body><freejoint/><geom type='box' size='{size} 0.1 0.1' material='m'/></body>"
        "</worldbody></mujoco>"
    )


def saved(model) -> bytes:
    """The model as MuJoCo writes it (MJB): every field and buffer."""
    buf = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return buf.tobytes()


class Counting:
    def __init__(self):
        self.calls = 0

    def __call__(self, xml, assets=None):
        self.calls += 1
        return mujoco.MjModel.from_xml_string(xml) if assets is None else mujoco.MjModel.from_xml_string(xml, assets)


def test_a_kept_model_is_the_compiled_one_byte_for_byte_and_each_copy_is_its_own():
    compile_xml = Counting()
    cache = CompiledModels(compile_xml)
    fresh = mujoco.MjModel.from_xml_string(scene(0.1))
    first, second = cache(scene(0.1)), cache(scene(0.1))
    assert compile_xml.calls == 2, "met once, an XML is compiled, not kept"
    got = cache(scene(0.1))
    assert compile_xml.calls == 2 and cache.hits == 1
    assert saved(got) == saved(fresh) == saved(first) == saved(second)
    # A caller's changes stay in its copy (robosuite sets the time step, offscreen sizes...).
    got.opt.timestep = 0.123
    got.geom_size[0, 0] = 9.0
    again = cache(scene(0.1))
    assert again is not got and saved(again) == saved(fresh)
    # And a simulation of the copy steps as one of a fresh compile does.
    a, b = mujoco.MjData(again), mujoco.MjData(fresh)
    for _ in range(50):
        mujoco.mj_step(again, a)
        mujoco.mj_step(fresh, b)
    assert a.qpos.tobytes() == b.qpos.tobytes()


def test_xml_drawn_at_every_reset_is_compiled_every_time_and_not_kept():
    compile_xml = Counting()
    cache = CompiledModels(compile_xml)
    sizes = [0.1 + i / 1000 for i in range(200)]
    for s in sizes:
        assert saved(cache(scene(s))) == saved(mujoco.MjModel.from_xml_string(scene(s)))
    assert compile_xml.calls == len(sizes) and cache.hits == 0
    assert not cache._models and len(cache._met) <= 64


def test_the_bound_drops_the_least_recently_used_and_a_model_over_it_is_never_kept():
    one = mujoco.MjModel.from_xml_string(scene(0.1)).nbuffer
    cache = CompiledModels(Counting(), max_bytes=int(2.5 * (one + len(scene(0.1)))))
    for s in (0.1, 0.2, 0.3):
        cache(scene(s))
        cache(scene(s))
    assert list(cache._models) == [scene(0.2), scene(0.3)]
    assert cache._bytes <= cache._max_bytes
    tiny = CompiledModels(Counting(), max_bytes=100)
    for _ in range(3):
        tiny(scene(0.1))
    assert not tiny._models and tiny.hits == 0


def test_in_memory_assets_are_compiled_every_time():
    compile_xml = Counting()
    cache = CompiledModels(compile_xml)
    xml = "<mujoco><asset><mesh name='m' file='tri.obj'/></asset><worldbody><geom type='mesh' mesh='m'/></worldbody></mujoco>"
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
    for _ in range(3):
        cache(xml, {"tri.obj": obj})
    assert compile_xml.calls == 3 and cache.hits == 0
