"""robosuite's sensor checks without a camera frame each: hard resets without 4 renders of 6.

robosuite (1.4 under LIBERO, and 1.5) checks each observable's sensor by calling it once, to
learn the shape of what it returns: when the observable is made and again when a hard reset
hands it the new simulation's sensor. For a camera that call renders a frame and throws it
away, so a hard reset with two cameras renders six frames to return two (LIBERO's kitchens
under Mesa's software renderer: 0.26 s of a 0.88 s reset). A camera sensor's shape follows from
what it was made with (camera, width, height, depth; the same code), so each such sensor is
checked for real once per worker and its shape reused after. Rendering reads the simulation
and writes nothing to it: the observations, camera images included, stay those of the suite
without this (`tests/python/pyenv/test_suites.py` counts the renders and compares the images).

The same hard reset ends robosuite 1.4's `MjSim.free` with a full `gc.collect()`, over every
object of every module imported so far (torch's and robosuite's, 270,000 objects: 0.16 s).
`freeze_imports()` moves what exists before the first env is made out of the collector's
reach (`gc.freeze`): modules live as long as the worker; what the envs make stays collectable.
"""

from __future__ import annotations

import gc
from typing import Any

#: robosuite's camera sensors (`RobotEnv._create_camera_sensors`), by the name of their code.
CAMERA_SENSORS = ("_create_camera_sensors.<locals>.camera_rgb",)
#: How many camera sensors' shapes are remembered (one per camera and size, usually 1 to 3).
MAX_SHAPES = 64

_shapes: dict[Any, tuple[int, ...]] = {}
_installed = False
_frozen = False


def install() -> bool:
    """Routes robosuite's `Observable._check_sensor_validity` through the shape cache
    (idempotent). False where robosuite's observables lack the method (not 1.4 or 1.5)."""
    global _installed
    if _installed:
        return True
    from robosuite.utils.observables import Observable

    check = getattr(Observable, "_check_sensor_validity", None)
    if check is None:
        return False

    def checked(observable: Any) -> None:
        key = camera_key(observable._sensor)
        shape = _shapes.get(key) if key is not None else None
        if shape is None:
            check(observable)
            if key is not None and len(_shapes) < MAX_SHAPES:
                _shapes[key] = observable._data_shape
            return
        _ = observable.modality  # what robosuite's check asserts besides the call
        observable._data_shape = shape
        observable._is_number = len(shape) == 1 and shape[0] == 1

    Observable._check_sensor_validity = checked
    _installed = True
    return True


def camera_key(sensor: Any) -> Any:
    """What a robosuite camera sensor's shape depends on: its code and the plain values it was
    made with (camera name, width, height, depth, image convention). None for any other
    sensor, or one that closes over a value other than those and its env."""
    if not getattr(sensor, "__qualname__", "").endswith(CAMERA_SENSORS):
        return None
    code = sensor.__code__
    values = []
    for name, cell in zip(code.co_freevars, sensor.__closure__ or ()):
        if name == "self":
            continue
        value = cell.cell_contents
        if not isinstance(value, (str, int, float, bool, type(None))):
            return None
        values.append((name, value))
    return (code, tuple(values))


def freeze_imports() -> None:
    """`gc.freeze()`, once per process, before its first env exists (see the module's doc)."""
    global _frozen
    if not _frozen:
        gc.freeze()
        _frozen = True
