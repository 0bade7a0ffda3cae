"""Offscreen render contexts kept across robosuite's hard resets of the same scene.

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
At most `MAX_KEPT` contexts wait for a simulation at once (one per env hosted is the usual).
"""

from __future__ import annotations

import hashlib
from typing import Any

#: Contexts waiting for the next simulation of their scene, at most.
MAX_KEPT = 4

_kept: list[Any] = []
_installed = False


def install() -> None:
    """Routes robosuite's simulations and offscreen contexts through the pool (idempotent; for
    robosuite 1.4, LIBERO's, and 1.5)."""
    global _installed
    if _installed:
        return
    import atexit

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
        sim._envhub_scene = hashlib.sha256(xml.encode()).digest()
        return sim

    def free(sim: Any) -> None:
        context = getattr(sim, "_render_context_offscreen", None)
        if context is not None and _reusable(context):
            sim._render_context_offscreen = None
            _keep(context)
        free_sim(sim)

    def uploaded(context: Any, tex_id: int) -> None:
        context._envhub_changed = True
        upload_texture(context, tex_id)

    def offscreen_context(sim: Any, device_id: int, max_width: int = 640, max_height: int = 480) -> Any:
        scene = getattr(sim, "_envhub_scene", None)
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
    # Freed while the interpreter is whole (at its finalisation, EGL's bindings may be gone).
    atexit.register(_kept.clear)
    _installed = True


def _reusable(context: Any) -> bool:
    return (
        getattr(context, "_envhub_key", None) is not None
        and not getattr(context, "_envhub_changed", False)
        and (context.con.offWidth, context.con.offHeight) == context._envhub_size
    )


def _keep(context: Any) -> None:
    context.sim = context.model = context.data = None
    _kept.append(context)
    while len(_kept) > MAX_KEPT:
        _kept.pop(0)  # freed as robosuite frees it (`__del__`)


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
