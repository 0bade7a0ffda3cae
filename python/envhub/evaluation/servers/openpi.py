"""OpenPI's policy-server protocol, client side: every server that OpenPI's
`serve_policy.py` (its `WebsocketPolicyServer`) or `openpi-client`'s protocol serves works
unchanged.

The wire, as `openpi-client` 0.1.2 speaks it: on connect the server sends its metadata (one
binary frame); then each request is one binary frame, the observation dict packed with
msgpack where numpy arrays are `{b"__ndarray__": True, b"data", b"dtype", b"shape"}`
(scalars `{b"__npgeneric__": ...}`), and its answer one binary frame, a dict with
`actions`: an action chunk `(action_horizon, action_dim)`. A server whose policy raised
sends the traceback as a text frame and closes the connection.

The protocol has no episodes: a connection serves whatever comes. One connection per env,
so a batch's requests are in flight together. The chunk comes back to the runner as
OpenPI's own clients use it: its first `replan_steps` actions are executed before the env
asks again (without `replan_steps`, the benchmark's `servers.openpi.replan`, LIBERO's 5 as
OpenPI's LIBERO example replans, else the whole chunk).
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

from ..policy import Request
from ._link import DEFAULT_TIMEOUT_S, ServerPolicy, SlotError, checked_action, is_image, wire_observation


class OpenPIPolicy(ServerPolicy):
    """An OpenPI policy server at `url` (`ws://host:port`) as a Policy.

    `fields` maps the server's observation keys to the benchmark's (`{"observation/image":
    "agentview_image", "observation/state": "state"}`, nested dicts joined by `.`); without
    it each entry `X` goes to `observation/X` (an array observation to `observation/image`
    or `observation/state`). The task's text goes to `prompt`. `replan_steps` is how many
    actions of each chunk run before the next request (OpenPI's LIBERO example uses 5).
    `timeout` bounds every wait for the server, in seconds."""

    kind = "openpi"

    def __init__(
        self,
        url: str,
        *,
        fields: dict[str, str] | None = None,
        replan_steps: int | None = None,
        timeout: float = DEFAULT_TIMEOUT_S,
        text_key: str = "prompt",
    ) -> None:
        if replan_steps is not None and replan_steps < 1:
            raise ValueError(
                f"replan_steps must be at least 1 (or None for the whole chunk), got {replan_steps}"
            )
        super().__init__(url, timeout=timeout)
        self.fields = dict(fields) if fields is not None else None
        self.replan_steps = replan_steps
        self.text_key = text_key

    def _layout(self, params: dict[str, Any]):
        return None if self.fields is not None else super()._layout(params)

    def replan(self) -> int | None:
        """Actions of each chunk run before the next request: `replan_steps`, else the
        benchmark's layout's (OpenPI's LIBERO example: 5), else the whole chunk."""
        if self.replan_steps is not None:
            return self.replan_steps
        return self.layout.replan if self.layout is not None and self.fields is None else None

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "replan_steps": self.replan()}

    async def _hello(self, ws: Any) -> dict[str, Any]:
        frame = await ws.recv()
        if isinstance(frame, str):
            raise SlotError(
                f"the OpenPI server at {self.url} sent text instead of its metadata: {_tail(frame)}"
            )
        try:
            metadata = unpackb(frame)
        except Exception as exc:
            raise SlotError(
                f"the OpenPI server at {self.url} sent metadata that is not msgpack: {exc}"
            ) from None
        return metadata if isinstance(metadata, dict) else {"metadata": metadata}

    def observation(self, request: Request) -> dict[str, Any]:
        """The observation dict sent for `request`: the benchmark's OpenPI layout (OpenPI's
        LIBERO example's keys, sizes and state for LIBERO), else `fields`, else the default."""
        if self.layout is not None and self.fields is None:
            return self.layout.observation(request.observation, request.episode.task.text)
        payload = wire_observation(request.observation, self.fields, _default_key)
        if self.text_key:
            payload.setdefault(self.text_key, request.episode.task.text)
        return payload

    async def _ask(self, ws: Any, request: Request) -> np.ndarray:
        await ws.send(packb(self.observation(request)))
        frame = await ws.recv()
        if isinstance(frame, str):
            raise SlotError(f"the OpenPI server at {self.url} failed: {_tail(frame)}")
        expected = "a dict with `actions`, an action chunk (action_horizon, action_dim)"
        try:
            answer = unpackb(frame)
        except Exception as exc:
            raise SlotError(
                f"the OpenPI server at {self.url} answered {len(frame)} bytes that are not msgpack ({exc}); expected {expected}"
            ) from None
        if not isinstance(answer, dict) or "actions" not in answer:
            got = (
                f"a dict with keys {sorted(map(str, answer))}"
                if isinstance(answer, dict)
                else type(answer).__name__
            )
            raise SlotError(f"the OpenPI server at {self.url} answered {got}; expected {expected}")
        try:
            actions = checked_action(answer["actions"], "`actions`")
        except SlotError as exc:
            raise SlotError(f"the OpenPI server at {self.url}: {exc}") from None
        replan = self.replan()
        if actions.ndim == 2 and replan is not None:
            actions = actions[:replan]
        return actions


def _default_key(name: str, value: Any) -> str:
    if name:
        return f"observation/{name}"
    return "observation/image" if is_image(value) else "observation/state"


def _tail(text: str) -> str:
    """What a server's traceback says failed (its last line), and where (its last frame)."""
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    if not lines:
        return "(an empty message)"
    frames = [line for line in lines if line.startswith("File ")]
    where = f" ({frames[-1]})" if frames else ""
    return f"{lines[-1][:400]}{where[:300]}"


def _pack_array(obj: Any) -> Any:
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.kind in ("V", "O", "c"):
        raise TypeError(f"OpenPI's msgpack carries no {obj.dtype} arrays")
    if isinstance(obj, np.ndarray):
        return {b"__ndarray__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": obj.shape}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise TypeError(f"cannot send {type(obj).__name__} to an OpenPI server")


def _unpack_array(obj: dict[Any, Any]) -> Any:
    if b"__ndarray__" in obj:
        dtype = np.dtype(obj[b"dtype"])
        if dtype.kind in ("V", "O", "c"):
            raise ValueError(f"an array of dtype {dtype}")
        return np.frombuffer(obj[b"data"], dtype=dtype).reshape(obj[b"shape"]).copy()
    if b"__npgeneric__" in obj:
        return np.dtype(obj[b"dtype"]).type(obj[b"data"])
    return obj


def packb(obj: Any) -> bytes:
    """`obj` as openpi-client's `msgpack_numpy.packb` writes it."""
    return msgpack.packb(obj, default=_pack_array, use_bin_type=True)


def unpackb(data: bytes) -> Any:
    """What openpi-client's `msgpack_numpy.unpackb` reads from `data`."""
    return msgpack.unpackb(data, object_hook=_unpack_array, raw=False, strict_map_key=False)
