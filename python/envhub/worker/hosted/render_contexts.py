"""Offscreen render contexts kept across robosuite 1.4's hard resets of the same scene (LIBERO).

A hard reset (robosuite's default, and LIBERO's evaluation's) frees the simulation and its
render context and builds both again: a new EGL context, and a `MjrContext` that uploads every
texture and mesh of the scene. For LIBERO's kitchens that upload is 190 MB of textures, 0.73 s
of a 1.7 s reset under Mesa's software renderer. When the new simulation was compiled from the
same XML as the old one, the context the old one rendered with holds exactly what a new one
would upload, so the worker hands it to the new simulation instead, set up as robosuite sets up
a new one (made current, a fresh scene, camera and options, the offscreen buffer selected).
The suites' tests compare the camera images of runs through envhub with the suite in-process,
which builds a context at every reset: bit for bit.

A context is handed on only when nothing changed it: not resized (`update_offscreen_size`) and
no texture uploaded since (robosuite's texture randomisation); otherwise it is freed as before.
Only contexts of a scene built more than once wait (robosuite's Lift draws its cube's size into
the XML at every reset), at most `MAX_KEPT` at once (one per env hosted is the usual); where
every scene is rebuilt as it is (LIBERO: `install(scenes_repeat=True)`), a scene's first context
waits too, so the reset that follows making an env reuses the context the env was made with. One
dropped from the pool is freed under its own GL context, made current for that (MuJoCo frees
textures and buffers in the current context: freed under another, they would be that one's),
just before a simulation's context is made current, as robosuite would make a new one.
"""

from __future__ import annotations

import atexit
import hashlib
from collections import OrderedDict
from typing import Any

#: Contexts waiting for the next simulation of their scene, at most.
MAX_KEPT = 4
#: How many scenes' build counts are remembered.
MAX_SCENES = 64

_kept: list[Any] = []
_dropped: list[Any] = []
_builds: OrderedDict[Any, int] = OrderedDict()
_installed = False
_exit_registered = False
#: Builds of a scene before its contexts wait for the next one (1 where scenes repeat).
_builds_to_keep = 2


def install(scenes_repeat: bool = False) -> bool:
    """Routes robosuite's simulations and offscreen contexts through the pool (idempotent), in
    robosuite 1.4 (LIBERO's) only: its hard reset frees the old simulation, and with it the
    context, which is then current. robosuite 1.5 drops the old simulation instead, and the
    garbage collector frees its context whenever it runs, under whichever context is current
    then: handed on, a context could lose its textures that way. False where not installed.
    `scenes_repeat`: every scene built is built again (LIBERO's hard resets rebuild the scene of
    the env's task), so a context waits from the scene's first build on."""
    global _installed, _builds_to_keep
    if scenes_repeat:
        _builds_to_keep = 1
    if _installed:
        return True
    import robosuite

    if not robosuite.__version__.startswith("1.4."):
        return False
    import robosuite.environments.base as base
    from robosuite.utils import binding_utils

    sim_class = binding_utils.MjSim
    context_class = binding_utils.MjRenderContext
    new_context = base.MjRenderContextOffscreen
    compile_sim = sim_class.from_xml_string.__func__
    free_sim = sim_class.free
    upload_texture = context_class.upload_texture

    def from_xml_string(cls: Any, xml: str) -> Any:
        sim = compile_sim(cls, xml)
        sim._envhub_scene = scene = hashlib.sha256(xml.encode()).digest()
        _builds[scene] = _builds.pop(scene, 0) + 1
        while len(_builds) > MAX_SCENES:
            _builds.popitem(last=False)
        return sim

    def free(sim: Any) -> None:
        _release(sim)
        free_sim(sim)

    def uploaded(context: Any, tex_id: int) -> None:
        context._envhub_changed = True
        upload_texture(context, tex_id)

    def offscreen_context(sim: Any, device_id: int, max_width: int = 640, max_height: int = 480) -> Any:
        scene = getattr(sim, "_envhub_scene", None)
        _free_dropped()
        key = None if scene is None else (scene, device_id, max_width, max_height)
        context = _take(key, sim) if key is not None else None
        if context is None:
            context = new_context(sim, device_id=device_id, max_width=max_width, max_height=max_height)
            context._envhub_key = key
            context._envhub_size = (context.con.offWidth, context.con.offHeight)
        else:
            _attach(context, sim)
        return context

    sim_class.from_xml_string = classmethod(from_xml_string)
    sim_class.free = free
    context_class.upload_texture = uploaded
    base.MjRenderContextOffscreen = offscreen_context
    _installed = True
    return True


def _release(sim: Any) -> None:
    """Takes the context of a simulation being dropped into the pool, if it can serve again."""
    context = getattr(sim, "_render_context_offscreen", None)
    if context is not None and _reusable(context):
        sim._render_context_offscreen = None
        _keep(context)


def _reusable(context: Any) -> bool:
    key = getattr(context, "_envhub_key", None)
    return (
        key is not None
        and _builds.get(key[0], 0) >= _builds_to_keep
        and not getattr(context, "_envhub_changed", False)
        and (context.con.offWidth, context.con.offHeight) == context._envhub_size
    )


def _keep(context: Any) -> None:
    global _exit_registered
    if not _exit_registered:
        # Freed before robosuite terminates EGL at exit (its handler, registered when it made
        # its first context, runs after this one).
        atexit.register(_free_all)
        _exit_registered = True
    context.sim = context.model = context.data = None
    _kept.append(context)
    while len(_kept) > MAX_KEPT:
        _dropped.append(_kept.pop(0))


def _free_all() -> None:
    _dropped.extend(_kept)
    _kept.clear()
    _free_dropped()


def _free_dropped() -> None:
    while _dropped:
        context = _dropped.pop()
        context.gl_ctx.make_current()
        context.con.free()
        # The last reference: robosuite's `__del__` frees the GL context (current: it unbinds it).
        del context


def _take(key: Any, sim: Any) -> Any:
    width, height = sim.model.vis.global_.offwidth, sim.model.vis.global_.offheight
    for i, context in enumerate(_kept):
        if context._envhub_key == key and context._envhub_size == (width, height):
            return _kept.pop(i)
    return None


def _attach(context: Any, sim: Any) -> None:
    """What robosuite's `MjRenderContext.__init__` does for a new simulation, less the GL
    context and the `MjrContext` (kept: they hold what a new one would upload)."""
    import mujoco

    context.sim = sim
    context.gl_ctx.make_current()
    sim.forward()
    sim.add_render_context(context)
    context.model = sim.model
    context.data = sim.data
    context.scn = mujoco.MjvScene(sim.model._model, maxgeom=context.scn.maxgeom)
    context.cam = mujoco.MjvCamera()
    context.cam.fixedcamid = 0
    context.cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
    context.vopt = mujoco.MjvOption()
    context.pert = mujoco.MjvPerturb()
    context.pert.active = 0
    context.pert.select = 0
    context.pert.skinselect = -1
    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, context.con)
