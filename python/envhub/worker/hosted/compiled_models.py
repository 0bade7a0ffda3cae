"""Each distinct MJCF compiled once per worker: robosuite's hard resets without the compile.

robosuite rebuilds its scene on every `reset()` by default: it serialises the MJCF trees of
its robots and of the whole scene and compiles them with `mujoco.MjModel.from_xml_string`,
most of a reset (robosuite 1.5's Lift: two compiles of 0.26 s each, of 0.55 s). The XML is the same reset after reset, and the same
XML compiles to the same model, so the worker keeps the models it compiled from an XML it met
twice, keyed by the XML text, and hands out copies (`mj_copyModel`, one copy of the model's buffer): the model a
compile would give, bit for bit (the suites' tests compare observations, camera images
included, with the suite run in-process without this cache). Files the XML names (meshes,
textures) are read when a model is first compiled and taken as unchanged while the worker runs.
A compile given `assets` (in-memory files) is not cached, nor is an XML met once: robosuite's Lift
draws its cube's size into the XML at every reset, so only its robot's model repeats. (LIBERO's
kitchens, 270 MB of model with their textures, would be over the bound: its adapter does not
use the cache; `render_contexts` saves the larger part of its resets.)
"""

from __future__ import annotations

import copy
import threading
from collections import OrderedDict
from typing import Any, Callable

#: The cache's bound, in bytes of compiled models (`MjModel.nbuffer`): a few scenes of the
#: largest suites (a LIBERO kitchen with its textures is tens of MB).
MAX_BYTES = 256 << 20
#: How many XMLs met once are remembered.
MAX_MET = 64


class CompiledModels:
    """`from_xml_string(xml, assets=None)` with the models compiled from an XML met twice kept,
    least recently used dropped first once they pass `max_bytes`."""

    def __init__(self, compile_xml: Callable[..., Any], max_bytes: int = MAX_BYTES) -> None:
        self._compile = compile_xml
        self._max_bytes = max_bytes
        self._models: OrderedDict[str, Any] = OrderedDict()
        self._bytes = 0
        #: Hashes of the XMLs met once (bounded: a suite that draws its XML at every reset
        #: would grow it without end).
        self._met: OrderedDict[int, None] = OrderedDict()
        self._lock = threading.Lock()
        self.compiles = 0
        self.hits = 0

    def __call__(self, xml: Any, assets: Any = None) -> Any:
        if assets is not None:
            return self._compile(xml, assets)
        if not isinstance(xml, str):
            return self._compile(xml)
        with self._lock:
            kept = self._models.get(xml)
            if kept is not None:
                self._models.move_to_end(xml)
                self.hits += 1
                return copy.copy(kept)
        model = self._compile(xml)
        self._keep(xml, model)
        return model

    def _keep(self, xml: str, model: Any) -> None:
        size = _size(xml, model)
        key = hash(xml)
        with self._lock:
            self.compiles += 1
            if key not in self._met:
                self._met[key] = None
                if len(self._met) > MAX_MET:
                    self._met.popitem(last=False)
                return
            if size > self._max_bytes or xml in self._models:
                return
            self._models[xml] = copy.copy(model)
            self._bytes += size
            while self._bytes > self._max_bytes:
                self._bytes -= _size(*self._models.popitem(last=False))


def _size(xml: str, model: Any) -> int:
    """What a kept model counts against the bound: its buffer and its XML key."""
    return int(getattr(model, "nbuffer", 0)) + len(xml)


_installed: CompiledModels | None = None


def install() -> CompiledModels:
    """Routes `mujoco.MjModel.from_xml_string` through one `CompiledModels` for this process
    (idempotent): a worker's interpreter hosts one suite, whose every compile goes there."""
    global _installed
    if _installed is None:
        import mujoco

        _installed = CompiledModels(mujoco.MjModel.from_xml_string)
        mujoco.MjModel.from_xml_string = staticmethod(_installed)
    return _installed
