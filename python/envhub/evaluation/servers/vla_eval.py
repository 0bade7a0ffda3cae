"""vla-eval's model-server protocol, client side: every model server written for vla-eval
(its `ModelServer` / `PredictModelServer` served by `vla_eval.model_servers.serve`) works
unchanged.

The wire, as vla-eval 0.8 speaks it: WebSocket binary frames, each one msgpack map
`{type, payload, seq, timestamp}` with `type` one of `hello`, `episode_start`,
`observation`, `action`, `episode_end`, `error`; numpy arrays travel as
`{"__ndarray__": true, data, dtype, shape}` (images may also come as `{"__image__": ...}`).
A connection says HELLO (and reads the server's HELLO: its version, protocol version 1,
action and observation specs), then per episode EPISODE_START `{"task": {...}}`, one
OBSERVATION per step answered by one ACTION `{"actions": array}` (echoing the
observation's `seq`) or an ERROR `{"error": text}`, and EPISODE_END `{metrics, steps,
elapsed_sec}`.

Batching is vla-eval's own: one connection per env (vla-eval opens one per shard), all of a
batch's observations in flight at once, and the server gathers them (`max_batch_size`).
Action chunks are the server's business in this protocol (`PredictModelServer(chunk_size=k)`
answers one action per observation from its buffer); a server that answers a whole chunk
`(k, action_dim)` has it executed as one, like the policy's other chunks.
"""

from __future__ import annotations

import itertools
import logging
import time
from typing import Any, Callable

import msgpack
import numpy as np

from ..policy import Episode, Request
from ._link import DEFAULT_TIMEOUT_S, ServerPolicy, SlotError, checked_action, is_image, wire_observation
from .layout import LayoutError

log = logging.getLogger("envhub.evaluation")

PROTOCOL_VERSION = 1
_NDARRAY = "__ndarray__"
_IMAGE = "__image__"


class VlaEvalPolicy(ServerPolicy):
    """A vla-eval model server at `url` (`ws://host:port`) as a Policy.

    `fields` maps the server's observation keys to the benchmark's (`{"images.agentview":
    "agentview_image", "states": "state"}`, nested dicts joined by `.`); without it every
    camera image `X_image` goes to `images.X` and every other entry keeps its name (an array
    observation goes to `states`, or `images.image` when it is an image). The task's text
    goes to `task_description`, as vla-eval's benchmarks send it. EPISODE_START's `task` says
    `name` (the task's text), `suite`, `task_id`, `episode_idx` and the episode's initial
    condition; `task_info(episode)` adds or replaces fields (a server that picks a model per
    task reads its own, e.g. `level`). `timeout` bounds every wait for the server, in seconds."""

    kind = "vla-eval"

    def __init__(
        self,
        url: str,
        *,
        fields: dict[str, str] | None = None,
        timeout: float = DEFAULT_TIMEOUT_S,
        text_key: str = "task_description",
        task_info: Callable[[Episode], dict[str, Any]] | None = None,
    ) -> None:
        super().__init__(url, timeout=timeout)
        self.task_info = task_info
        self.fields = dict(fields) if fields is not None else None
        self.text_key = text_key
        # The observation params the server asked for at its first HELLO (every later
        # connection must ask the same).
        self._bound_params: dict[str, Any] | None = None
        self._binding = False
        self._seq = itertools.count(1)
        self._seq_warned = False

    async def _send(self, ws: Any, kind: str, payload: dict[str, Any]) -> int:
        seq = next(self._seq)
        await ws.send(pack(kind, payload, seq))
        return seq

    async def _recv(self, ws: Any) -> dict[str, Any]:
        return unpack(await ws.recv(), self.url)

    async def _hello(self, ws: Any) -> dict[str, Any]:
        from ... import _envhub

        await self._send(
            ws, "hello", {"harness_version": f"envhub {_envhub.__version__}", "protocol_version": PROTOCOL_VERSION}
        )
        reply = await self._recv(ws)
        if reply["type"] != "hello":
            raise SlotError(
                f"the vla-eval server at {self.url} answered HELLO with {reply['type'].upper()}; expected HELLO"
            )
        info = reply["payload"] if isinstance(reply["payload"], dict) else {}
        version = info.get("protocol_version", PROTOCOL_VERSION)
        if version != PROTOCOL_VERSION:
            raise SlotError(
                f"the vla-eval server at {self.url} speaks protocol version {version}; "
                f"envhub speaks version {PROTOCOL_VERSION}"
            )
        params = _params(info, self.url)
        if self._bound_params is not None and params != self._bound_params:
            raise SlotError(
                f"the vla-eval server at {self.url} now asks for the observation params {params}; the "
                f"evaluation began with {self._bound_params}"
            )
        if self._bound_params is None and not self._binding:
            # A client used without `bind`: the asks are checked here, once.
            self.layout = self._layout(params)
        self._bound_params = params
        return info

    def _asked_params(self) -> dict[str, Any]:
        import concurrent.futures

        from ..policy import PolicyError
        from ._link import _LOOP_GRACE_S

        if self._bound_params is not None:
            return dict(self._bound_params)
        self._binding = True
        try:
            self._submit(self._probe()).result(timeout=4 * self.timeout + _LOOP_GRACE_S)
        except SlotError as exc:
            raise PolicyError(str(exc)) from None
        except concurrent.futures.TimeoutError:
            raise PolicyError(f"the vla-eval server at {self.url} did not say hello within {self.timeout:g} s") from None
        finally:
            self._binding = False
        return dict(self._bound_params or {})

    def _layout(self, params: dict[str, Any]):
        if self.fields is not None:
            asked = {k: v for k, v in params.items() if v}
            if asked:
                raise LayoutError(
                    f"the vla-eval server at {self.url} asks for the observation params {asked}; with `fields` "
                    f"envhub sends exactly the fields given ({sorted(self.fields)})"
                )
            return None
        return super()._layout(params)

    async def _begin(self, ws: Any, episode: Episode) -> None:
        task = episode.task
        # What vla-eval's runner sends: the task's scalar fields (`name` is the instruction
        # in vla-eval's LIBERO; `suite`, `task_id`, `episode_idx` as its benchmarks name them).
        info: dict[str, Any] = {
            "name": task.text or task.id,
            "suite": task.benchmark,
            "task_id": task.index,
            "episode_idx": episode.index,
            "envhub_task": task.id,
            "envhub_entry": task.entry,
        }
        info.update({k: v for k, v in episode.init.items() if isinstance(v, (str, int, float, bool, list))})
        if self.task_info is not None:
            info.update(self.task_info(episode))
        await self._send(ws, "episode_start", {"task": info})

    def observation(self, request: Request) -> dict[str, Any]:
        """The OBSERVATION payload for `request`: the benchmark's vla-eval layout under the
        server's observation params, else `fields`, else the default layout."""
        if self.layout is not None:
            return self.layout.observation(request.observation, request.episode.task.text)
        payload = wire_observation(request.observation, self.fields, _default_key)
        if self.text_key:
            payload.setdefault(self.text_key, request.episode.task.text)
        return payload

    async def _ask(self, ws: Any, request: Request) -> np.ndarray:
        seq = await self._send(ws, "observation", self.observation(request))
        reply = await self._recv(ws)
        what = "an ACTION message whose payload's `actions` is the action"
        if reply["type"] == "error":
            detail = reply["payload"].get("error") if isinstance(reply["payload"], dict) else reply["payload"]
            raise SlotError(f"the vla-eval server at {self.url} answered ERROR: {detail}")
        if reply["type"] != "action":
            raise SlotError(
                f"the vla-eval server at {self.url} answered {reply['type'].upper()}; expected {what}"
            )
        if reply["seq"] != seq and not self._seq_warned:
            # vla-eval's own client only warns here: a server may number its answers its own way.
            self._seq_warned = True
            log.warning("%s: ACTION seq %s answers OBSERVATION seq %s", self.url, reply["seq"], seq)
        payload = reply["payload"]
        if not isinstance(payload, dict):
            raise SlotError(
                f"the vla-eval server at {self.url} answered an ACTION of {type(payload).__name__}; expected {what}"
            )
        value = payload.get("actions", payload.get("action"))
        try:
            return checked_action(value, "`actions`")
        except SlotError as exc:
            raise SlotError(f"the vla-eval server at {self.url}: {exc}") from None

    async def _finish(self, ws: Any, episode: Episode, result: dict[str, Any]) -> None:
        metrics = {k: result[k] for k in ("success", "return") if k in result}
        payload = {"metrics": metrics, "steps": int(result.get("length", 0) or 0)}
        if "seconds" in result:
            payload["elapsed_sec"] = round(float(result["seconds"]), 3)
        if result.get("error"):
            payload["error"] = str(result["error"])
        await self._send(ws, "episode_end", payload)


def _params(info: dict[str, Any], url: str) -> dict[str, Any]:
    params = info.get("observation_params") or {}
    if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
        raise SlotError(f"the vla-eval server at {url} sent `observation_params` {params!r}; expected a mapping")
    return dict(params)


def _default_key(name: str, value: Any) -> str:
    if is_image(value):
        camera = name.removesuffix("_image") if name else "image"
        return f"images.{camera or 'image'}"
    return name or "states"


def _encode(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"vla-eval carries bool/int/uint/float arrays, not {obj.dtype}")
        return {_NDARRAY: True, "data": obj.tobytes(), "dtype": obj.dtype.str, "shape": list(obj.shape)}
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    raise TypeError(f"cannot send {type(obj).__name__} to a vla-eval server")


def _decode(obj: dict[Any, Any]) -> Any:
    if _IMAGE in obj:
        if obj.get("format") != "raw":
            return _decode_compressed(obj)
        return _array(obj)
    if _NDARRAY in obj:
        return _array(obj)
    return obj


def _array(obj: dict[Any, Any]) -> np.ndarray:
    dtype = np.dtype(obj["dtype"])
    if dtype.kind not in "biuf":
        raise ValueError(f"an array of dtype {dtype}; vla-eval carries bool/int/uint/float")
    return np.frombuffer(obj["data"], dtype=dtype).reshape(obj["shape"]).copy()


def _decode_compressed(obj: dict[Any, Any]) -> np.ndarray:
    import io

    try:
        from PIL import Image
    except ImportError:
        raise ValueError(f"a {obj.get('format')} image, which needs Pillow to decode") from None
    return np.array(Image.open(io.BytesIO(obj["data"])))


def pack(kind: str, payload: dict[str, Any], seq: int) -> bytes:
    """One vla-eval message as its bytes on the wire."""
    message = {"type": kind, "payload": payload, "seq": seq, "timestamp": time.time()}
    return msgpack.packb(message, default=_encode, use_bin_type=True)


def unpack(data: Any, url: str = "the server") -> dict[str, Any]:
    """One vla-eval message from its bytes; SlotError naming what is wrong with it."""
    if isinstance(data, str):
        raise SlotError(
            f"the vla-eval server at {url} sent a text frame ({data[:200]!r}); expected a msgpack message"
        )
    try:
        message = msgpack.unpackb(data, object_hook=_decode, raw=False)
    except Exception as exc:
        raise SlotError(
            f"the vla-eval server at {url} sent {len(data)} bytes that are not a vla-eval message: {exc}"
        ) from None
    missing = [k for k in ("type", "payload", "seq") if not isinstance(message, dict) or k not in message]
    if missing:
        raise SlotError(
            f"the vla-eval server at {url} sent a message without {missing}; expected {{type, payload, seq, timestamp}}"
        )
    if message["type"] not in _TYPES:
        raise SlotError(
            f"the vla-eval server at {url} sent a message of type {message['type']!r}; valid: {sorted(_TYPES)}"
        )
    return message


_TYPES = frozenset({"hello", "observation", "action", "episode_start", "episode_end", "error"})
