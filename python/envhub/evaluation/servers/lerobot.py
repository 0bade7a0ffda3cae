"""LeRobot's async-inference policy server (LeRobot 0.6.1, `lerobot.async_inference.
policy_server`, gRPC), client side: the server runs unchanged, started with LeRobot's own
entry point; envhub speaks its protocol with `grpcio` alone (an optional dependency: `pip
install 'grpcio>=1.73'`), so neither LeRobot nor torch nor protobuf live in envhub's
interpreter.

The wire, as LeRobot 0.6.1's `robot_client.py` speaks it (`transport/services.proto`,
service `transport.AsyncInference`): `Ready(Empty)` (the server drops its state),
`SendPolicyInstructions(PolicySetup{data})` with a pickled `RemotePolicyConfig` (policy
type, checkpoint path, the observation's dataset features, actions per chunk, device: the
server loads the policy), then per request `SendObservations(stream Observation
{transfer_state, data})` with a pickled `TimedObservation` (the raw observation dict:
state entries by name, camera images HWC uint8, `task`) in 2 MiB chunks, and
`GetActions(Empty) -> Actions{data}`, a pickled list of `TimedAction` whose actions are
torch tensors. The messages are a few protobuf fields, encoded here; the pickles the server
reads name LeRobot's classes and are written here without them; the answer is read by an
unpickler that admits only `TimedAction`, torch's tensor rebuild and its storages (read from
their bytes), so nothing else the server sends runs.

The server serves one client and one observation at a time: a batch's requests go one
after the other, each observation `must_go`. It has no episodes.
"""

from __future__ import annotations

import io
import pickle
import struct
import threading
import time
from typing import Any, Sequence
from urllib.parse import parse_qsl, urlsplit

import numpy as np

from ..policy import Episode, PolicyError, Request
from ._link import DEFAULT_TIMEOUT_S, is_image

_SERVICE = "/transport.AsyncInference/"
_CHUNK = 2 * 1024 * 1024  # LeRobot's transport chunk (transport/utils.py)
_BEGIN, _MIDDLE, _END = 1, 2, 3  # TransferState
_HELPERS = "lerobot.async_inference.helpers"
_INSTALL = "pip install 'grpcio>=1.73'"


class LeRobotPolicy:
    """A LeRobot async-inference policy server as a Policy.

    `url`: `lerobot://host:port?policy_type=act&pretrained=PATH` (also `grpc://`), with
    optional `actions_per_chunk` (default 50), `device` (default cpu), `images` (`key:name,..`:
    the observation's images and the names the policy's `observation.images.<name>`
    features have; default each `X_image` as `X`), `state` (`key,..`: the entries
    concatenated into `observation.state`, in order; default every non-image entry) and
    `rename.<from>=<to>` (LeRobot's `rename_map`). Keyword arguments override the query.
    `timeout` bounds each call (loading the policy included), in seconds."""

    kind = "lerobot"

    def __init__(self, url: str, *, timeout: float = DEFAULT_TIMEOUT_S, **options: Any) -> None:
        try:
            import grpc
        except ImportError:
            raise PolicyError(f"the lerobot server protocol needs grpcio in envhub's interpreter: {_INSTALL}") from None
        self._grpc = grpc
        parts = urlsplit(url if "://" in url else f"lerobot://{url}")
        if parts.scheme not in ("lerobot", "grpc") or not parts.hostname or not parts.port:
            raise ValueError(f"a LeRobot policy server's URL is lerobot://host:port?policy_type=..&pretrained=.., not {url!r}")
        query = dict(parse_qsl(parts.query))
        query.update({k: str(v) for k, v in options.items()})
        missing = [k for k in ("policy_type", "pretrained") if not query.get(k)]
        if missing:
            raise ValueError(
                f"the LeRobot server at {url} needs {' and '.join(missing)} (what it loads: "
                "lerobot://host:port?policy_type=act&pretrained=/path/to/checkpoint)"
            )
        known = {"policy_type", "pretrained", "actions_per_chunk", "device", "images", "state"}
        unknown = sorted(k for k in query if k not in known and not k.startswith("rename."))
        if unknown:
            raise ValueError(f"unknown LeRobot server options {unknown}; valid: {sorted(known)} and rename.<key>")
        if not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        self.url = f"lerobot://{parts.hostname}:{parts.port}"
        self.target = f"{parts.hostname}:{parts.port}"
        self.timeout = float(timeout)
        self.policy_type = query["policy_type"]
        self.pretrained = query["pretrained"]
        self.actions_per_chunk = int(query.get("actions_per_chunk", 50))
        self.device = query.get("device", "cpu")
        self.images = _pairs(query["images"]) if "images" in query else None
        self.state = [k for k in query["state"].split(",") if k] if "state" in query else None
        self.rename = {k[len("rename."):]: v for k, v in query.items() if k.startswith("rename.")}
        self._lock = threading.Lock()
        self._channel: Any = None
        self._features: dict[str, Any] | None = None
        self._timestep = 0
        self._closed = False

    # -- the Policy interface -------------------------------------------------------------

    def start(self, slot: int, episode: Episode) -> None:
        pass

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        pass

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        with self._lock:
            answers = []
            for request in requests:
                raw, features = self._raw(request)
                where = f"episode {request.episode.key} at step {request.step}"
                try:
                    self._ensure(features)
                    answers.append(self._ask(raw, where))
                except PolicyError:
                    self._drop()
                    raise
            return answers

    def describe(self) -> dict[str, Any]:
        return {
            "kind": "server",
            "protocol": self.kind,
            "name": self.url,
            "url": self.url,
            "timeout_s": self.timeout,
            "server": {
                "policy_type": self.policy_type,
                "pretrained": self.pretrained,
                "actions_per_chunk": self.actions_per_chunk,
                "device": self.device,
            },
        }

    def close(self) -> None:
        self._closed = True
        self._drop()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the observation as LeRobot's robot client sends it -------------------------------------

    def _raw(self, request: Request) -> tuple[dict[str, Any], dict[str, Any]]:
        """The raw observation (state entries by name, images by camera name, `task`) and
        its dataset features (`observation.state`, `observation.images.<camera>`)."""
        obs = request.observation
        if not isinstance(obs, dict):
            obs = {"state": obs}
        images = self.images
        if images is None:
            images = {k: k.removesuffix("_image") for k, v in obs.items() if is_image(np.asarray(v))}
        state_keys = self.state if self.state is not None else [k for k in obs if k not in images]
        for key in [*images, *state_keys]:
            if key not in obs:
                raise PolicyError(f"the observation has no key {key!r} (for the LeRobot server); it has {sorted(obs)}")
        raw: dict[str, Any] = {}
        names: list[str] = []
        for key in state_keys:
            values = np.asarray(obs[key], dtype=np.float64).ravel()
            for i, x in enumerate(values):
                name = key if values.size == 1 and np.ndim(obs[key]) == 0 else f"{key}.{i}"
                raw[name] = float(x)
                names.append(name)
        features: dict[str, Any] = {}
        if names:
            features["observation.state"] = {"dtype": "float32", "shape": (len(names),), "names": names}
        for key, camera in images.items():
            image = np.ascontiguousarray(obs[key])
            raw[camera] = image
            features[f"observation.images.{camera}"] = {
                "dtype": "image",
                "shape": tuple(image.shape),
                "names": ["height", "width", "channels"],
            }
        raw["task"] = request.episode.task.text
        return raw, features

    # -- the calls ------------------------------------------------------------------------

    def _call(self, method: str, request: Any, what: str, stream: bool = False) -> bytes:
        grpc = self._grpc
        if stream:
            call = self._channel.stream_unary(_SERVICE + method, request_serializer=bytes, response_deserializer=bytes)
        else:
            call = self._channel.unary_unary(_SERVICE + method, request_serializer=bytes, response_deserializer=bytes)
        try:
            return call(request, timeout=self.timeout)
        except grpc.RpcError as exc:
            code = exc.code() if hasattr(exc, "code") else None
            if code == grpc.StatusCode.DEADLINE_EXCEEDED:
                raise PolicyError(
                    f"the LeRobot server at {self.url} did not answer {method} within {self.timeout:g} s "
                    f"(--policy-timeout; {what})"
                ) from None
            detail = exc.details() if hasattr(exc, "details") else str(exc)
            raise PolicyError(f"the LeRobot server at {self.url} failed {method} ({what}): {code}: {detail}") from None

    def _ensure(self, features: dict[str, Any]) -> None:
        """Connects and sends the policy instructions (again when the features change)."""
        if self._closed:
            raise PolicyError(f"the LeRobot client for {self.url} is closed")
        if self._channel is not None and features == self._features:
            return
        if self._channel is None:
            self._channel = self._grpc.insecure_channel(
                self.target,
                options=[("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)],
            )
        self._call("Ready", b"", "its Ready call")
        config = {
            "policy_type": self.policy_type,
            "pretrained_name_or_path": self.pretrained,
            "lerobot_features": features,
            "actions_per_chunk": self.actions_per_chunk,
            "device": self.device,
            "rename_map": dict(self.rename),
        }
        setup = _instance(_HELPERS, "RemotePolicyConfig", config)
        self._call("SendPolicyInstructions", _field_bytes(1, setup), "loading the policy")
        self._features = features

    def _ask(self, raw: dict[str, Any], where: str) -> np.ndarray:
        timestep = self._timestep
        self._timestep += 1
        state = {"timestamp": time.time(), "timestep": timestep, "observation": raw, "must_go": True}
        data = _instance(_HELPERS, "TimedObservation", state)
        chunks = [data[i : i + _CHUNK] for i in range(0, len(data), _CHUNK)] or [b""]
        messages = []
        for i, chunk in enumerate(chunks):
            transfer = _END if i == len(chunks) - 1 else (_BEGIN if i == 0 else _MIDDLE)
            messages.append(_varint_field(1, transfer) + _field_bytes(2, chunk))
        self._call("SendObservations", iter(messages), where, stream=True)
        answer = _read_field_bytes(self._call("GetActions", b"", where), 1)
        if not answer:
            raise PolicyError(
                f"the LeRobot server at {self.url} answered no actions ({where}): it had no observation to run "
                "within its obs_queue_timeout, or its policy failed (its log says which)"
            )
        try:
            timed = _ActionUnpickler(io.BytesIO(answer)).load()
            actions = np.stack([np.asarray(t.action, dtype=np.float32).reshape(-1) for t in timed])
        except Exception as exc:
            raise PolicyError(
                f"the LeRobot server at {self.url} answered {len(answer)} bytes that are not a list of TimedAction "
                f"({where}): {exc}"
            ) from None
        return actions

    def _drop(self) -> None:
        channel, self._channel, self._features = self._channel, None, None
        if channel is not None:
            channel.close()


def _pairs(text: str) -> dict[str, str]:
    out = {}
    for part in text.split(","):
        if part:
            key, _, name = part.partition(":")
            out[key] = name or key.removesuffix("_image")
    return out


# -- protobuf: the few fields of LeRobot's messages -----------------------------------------


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _varint_field(number: int, value: int) -> bytes:
    return _varint(number << 3) + _varint(value) if value else b""


def _field_bytes(number: int, data: bytes) -> bytes:
    return _varint((number << 3) | 2) + _varint(len(data)) + data if data else b""


def _read_field_bytes(message: bytes, number: int) -> bytes:
    """The bytes field `number` of a protobuf message (the last one, as protobuf reads it)."""
    pos, found = 0, b""
    while pos < len(message):
        key, pos = _read_varint(message, pos)
        kind = key & 7
        if kind == 0:
            _, pos = _read_varint(message, pos)
        elif kind == 2:
            size, pos = _read_varint(message, pos)
            if key >> 3 == number:
                found = message[pos : pos + size]
            pos += size
        elif kind in (1, 5):
            pos += 8 if kind == 1 else 4
        else:
            raise PolicyError(f"a protobuf message with wire type {kind}")
    return found


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    shift = result = 0
    while True:
        if pos >= len(data):
            raise PolicyError("a truncated protobuf message")
        byte = data[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return result, pos
        shift += 7


# -- pickles: LeRobot's classes written without LeRobot, torch tensors read without torch -----


def _instance(module: str, name: str, state: dict[str, Any]) -> bytes:
    """A pickle of `module.name` made with `__new__` and `state` as its `__dict__` (how a
    dataclass unpickles), written without importing `module`."""
    body = pickle.dumps(state, protocol=2)
    # PROTO 2 | GLOBAL module name | EMPTY_TUPLE | NEWOBJ | <state> | BUILD | STOP
    return b"\x80\x02c" + f"{module}\n{name}\n".encode() + b")\x81" + body[2:-1] + b"b."


class _Timed:
    """A `TimedAction` as read here (its `__dict__`: timestamp, timestep, action)."""

    action: Any = None


_STORAGES = {
    "FloatStorage": np.float32,
    "DoubleStorage": np.float64,
    "HalfStorage": np.float16,
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}


class _Storage:
    def __init__(self, dtype: Any) -> None:
        self.dtype = np.dtype(dtype)


def _rebuild_tensor(storage: np.ndarray, offset: int, size: tuple, stride: tuple, *_: Any) -> np.ndarray:
    if not isinstance(storage, np.ndarray):
        raise pickle.UnpicklingError("a tensor whose storage is not one")
    needed = offset + sum((n - 1) * s for n, s in zip(size, stride)) + 1 if all(size) else 0
    if offset < 0 or any(s < 0 for s in stride) or needed > storage.size:
        raise pickle.UnpicklingError(f"a tensor of size {size} and stride {stride} outside its storage of {storage.size}")
    item = storage.itemsize
    view = np.lib.stride_tricks.as_strided(
        storage[offset:], shape=tuple(size), strides=tuple(s * item for s in stride), writeable=False
    )
    return np.array(view)


def _load_storage(data: bytes) -> np.ndarray:
    """A storage as torch's legacy `torch.save` wrote it (what `pickle.dumps(tensor)` embeds):
    magic number, protocol version, system info, the storage pickled with a persistent id,
    the storage keys, then each storage's element count and bytes."""
    f = io.BytesIO(data)
    _Plain(f).load()  # magic number
    _Plain(f).load()  # protocol version
    _Plain(f).load()  # system info
    found: dict[str, tuple[np.dtype, int]] = {}

    class Records(_Plain):
        def persistent_load(self, pid: Any) -> Any:
            # ("storage", type, key, location, numel[, view metadata: None for a whole storage])
            if not (isinstance(pid, tuple) and len(pid) in (5, 6) and pid[0] == "storage" and pid[5:] in ((), (None,))):
                raise pickle.UnpicklingError(f"an unexpected persistent id {pid!r}")
            _, kind, key, _location, numel = pid[:5]
            if not isinstance(kind, _Storage):
                raise pickle.UnpicklingError(f"a storage of type {kind!r}")
            found[str(key)] = (kind.dtype, int(numel))
            return str(key)

        def find_class(self, module: str, name: str) -> Any:
            if module == "torch" and name in _STORAGES:
                return _Storage(_STORAGES[name])
            return super().find_class(module, name)

    root = Records(f).load()
    keys = _Plain(f).load()
    arrays = {}
    for key in keys:
        dtype, _ = found[key]
        (count,) = struct.unpack("<q", f.read(8))
        raw = f.read(count * dtype.itemsize)
        if len(raw) != count * dtype.itemsize:
            raise pickle.UnpicklingError("a storage shorter than its element count")
        arrays[key] = np.frombuffer(raw, dtype=dtype)
    if root not in arrays:
        raise pickle.UnpicklingError("a storage record without its bytes")
    return arrays[root]


class _Plain(pickle.Unpickler):
    """An unpickler that admits no class or function."""

    def find_class(self, module: str, name: str) -> Any:
        raise pickle.UnpicklingError(f"the server's answer names {module}.{name}, which envhub does not load")


class _ActionUnpickler(_Plain):
    """Reads a pickled list of LeRobot's `TimedAction`: its class, torch's tensor rebuild and
    storages, `OrderedDict` (a tensor's backward hooks), nothing else."""

    def find_class(self, module: str, name: str) -> Any:
        allowed = {
            (_HELPERS, "TimedAction"): _Timed,
            ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor,
            ("torch.storage", "_load_from_bytes"): _load_storage,
            ("collections", "OrderedDict"): dict,
        }
        if (module, name) in allowed:
            return allowed[(module, name)]
        return super().find_class(module, name)
