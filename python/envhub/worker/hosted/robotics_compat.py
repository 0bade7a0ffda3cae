"""Gymnasium-Robotics 1.4.2 under `mujoco` >= 3.12.

MuJoCo 3.12 moved to pybind11 3.1, where `mjtJoint.mjJNT_HINGE == np.int32(3)` is False
while `np.int32(3) == mjtJoint.mjJNT_HINGE` is True. `gymnasium_robotics.utils.mujoco_utils`
tests `joint_type in (mjJNT_HINGE, mjJNT_SLIDE)`, which compares from the enum's side, so
every Fetch, Shadow-hand and Franka-kitchen env fails an assertion while being built. The
native MuJoCo adapter links libmujoco 3.17 and its parity tests need the same `mujoco` in
Python, so downgrading is not an option.

The fix is scoped to that one module: its `mujoco` name is pointed at a view of the real
module whose `mjtJoint` members are plain ints (which compare correctly from both sides).
It is applied only when the asymmetry is present, and the upstream code is left untouched.
"""

from __future__ import annotations

import types
from typing import Any

_PATCHED = "_envhub_int_joint_types"


def _enum_compare_broken(mujoco: Any) -> bool:
    import numpy as np

    hinge = mujoco.mjtJoint.mjJNT_HINGE
    return np.int32(int(hinge)) not in (hinge,)


class _IntJointTypes(types.SimpleNamespace):
    """`mujoco.mjtJoint` with int members."""


class _MujocoView(types.ModuleType):
    """The `mujoco` module, except that `mjtJoint` has int members."""

    def __init__(self, mujoco: Any) -> None:
        super().__init__(mujoco.__name__, mujoco.__doc__)
        self._mujoco = mujoco
        members = {name: int(getattr(mujoco.mjtJoint, name)) for name in dir(mujoco.mjtJoint) if name.startswith("mjJNT_")}
        self.mjtJoint = _IntJointTypes(**members)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._mujoco, name)


def apply() -> bool:
    """Makes Gymnasium-Robotics' joint helpers work under this `mujoco`; True when a fix was
    needed (and is now in place)."""
    import mujoco
    from gymnasium_robotics.utils import mujoco_utils

    if getattr(mujoco_utils, _PATCHED, False):
        return True
    if not _enum_compare_broken(mujoco):
        return False
    mujoco_utils.mujoco = _MujocoView(mujoco)
    setattr(mujoco_utils, _PATCHED, True)
    return True
