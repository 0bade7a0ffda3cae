"""Autoreset modes: Gymnasium's `AutoresetMode` and the names the data plane uses
(`next_step`, `same_step`, `disabled`)."""

from __future__ import annotations

from gymnasium.vector import AutoresetMode

from .errors import InvalidConfigError

RUST_MODES = {
    AutoresetMode.NEXT_STEP: "next_step",
    AutoresetMode.SAME_STEP: "same_step",
    AutoresetMode.DISABLED: "disabled",
}


def autoreset_mode(mode: str | AutoresetMode) -> AutoresetMode:
    """Gymnasium's enum from itself, its value (`"NextStep"`) or envhub's name (`"next_step"`)."""
    if isinstance(mode, AutoresetMode):
        return mode
    for m, name in RUST_MODES.items():
        if isinstance(mode, str) and mode.lower().replace("-", "_") in (name, m.value.lower(), name.replace("_", "")):
            return m
    raise InvalidConfigError(
        f"unknown autoreset mode `{mode}`; valid modes are `next_step`, `same_step`, `disabled` "
        "(or gymnasium.vector.AutoresetMode)"
    )
