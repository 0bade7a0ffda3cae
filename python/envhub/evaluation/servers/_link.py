"""What the two policy-server clients share: one WebSocket per env slot, driven from an
asyncio loop on a thread of its own, every wait bounded.

The runner's thread calls `start` / `act` / `end`; each becomes a coroutine on the loop.
A batch of requests goes out at once, one request per slot's connection, and its answers
are awaited together, so a server that batches across connections (vla-eval's
`PredictModelServer` with `max_batch_size > 1`) sees the whole batch, and a server that
answers one connection at a time still gets them back to back. The operations on one slot
run in the order they were called (a per-slot lock, FIFO in asyncio), so an episode's end
always reaches the server before the next episode's start.

A slot whose connection failed (closed, stalled past the timeout, answered something that
is not an action) has it dropped; its next episode connects anew.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..policy import Episode, PolicyError, Request
from .layout import Layout, LayoutError, layout_for

log = logging.getLogger("envhub.evaluation")

# What the thread waiting for a batch adds to the server timeout before it gives up on the
# loop itself (the loop's own timeouts fire first; this only guards against a stuck loop).
_LOOP_GRACE_S = 5.0
# How long closing a connection may take before it is abandoned.
_CLOSE_TIMEOUT_S = 1.0
#: Seconds each wait for a server may take by default (`--policy-timeout`).
DEFAULT_TIMEOUT_S = 120.0


class SlotError(Exception):
    """One slot's failure inside a batch: becomes part of the batch's PolicyError."""


@dataclass
class _Link:
    """A slot's connection and the episode it is in."""

    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    ws: Any = None
    episode: Episode | None = None
    # The failure of the current episode's start, reported by its first `act`.
    start_error: str | None = None


class ServerPolicy:
    """A Policy whose actions come from a server over WebSocket (one connection per slot).

    Subclasses speak a protocol: `_hello` after connecting, `_begin` / `_ask` / `_finish`
    per episode. `timeout` bounds every wait (connecting, the handshake, each answer)."""

    kind = "server"

    def __init__(self, url: str, *, timeout: float = DEFAULT_TIMEOUT_S) -> None:
        if not url.startswith(("ws://", "wss://")):
            url = f"ws://{url}"
        if not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        self.url = url
        self.timeout = float(timeout)
        self.server_info: dict[str, Any] = {}
        # The benchmark's `servers:` declaration and name (`bind`), and the wire layout
        # they give with what the server asked for (None: the protocol's default layout).
        self._servers_decl: dict[str, Any] | None = None
        self._benchmark = "this benchmark"
        self._protocol_values: dict[str, Any] = {}
        self.layout: Layout | None = None
        self._links: dict[int, _Link] = {}
        self._pending: set[concurrent.futures.Future] = set()
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(
            target=self._loop.run_forever, name=f"envhub-{self.kind}", daemon=True
        )
        self._thread.start()
        self._closed = False

    # -- the Policy interface, called from the runner's thread --------------------------

    def start(self, slot: int, episode: Episode) -> None:
        """Begins `episode` on `slot` without waiting: a failure to connect or to start
        fails the episode's first `act`."""
        self._submit(self._start(slot, episode))

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        if not requests:
            return []
        future = self._submit(self._act(list(requests)))
        try:
            # Connecting, the handshake, the episode's start and the answer are each bounded
            # by `timeout` on the loop; this bound only guards against a stuck loop.
            answers = future.result(timeout=4 * self.timeout + _LOOP_GRACE_S)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise PolicyError(
                f"the {self.kind} client for {self.url} gave no answer within {4 * self.timeout:g} s "
                f"for slots {[r.slot for r in requests]}"
            ) from None
        failed = {r.slot: a for r, a in zip(requests, answers) if isinstance(a, SlotError)}
        if failed:
            lines = "; ".join(f"slot {slot}: {err}" for slot, err in failed.items())
            error = PolicyError(lines)
            # Which slots failed and why, for a runner that fails only those episodes.
            error.slots = {slot: str(err) for slot, err in failed.items()}  # type: ignore[attr-defined]
            # The other slots' answers (None where a slot failed), for that runner to use.
            error.answers = [None if isinstance(a, SlotError) else a for a in answers]  # type: ignore[attr-defined]
            raise error
        return answers

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        self._submit(self._end(slot, episode, result))

    def bind(self, bench: Any) -> Any:
        """Takes the benchmark's `servers:` layout for this protocol (asking the server, for a
        protocol whose servers say what they need, now) and returns the benchmark with what
        that layout needs of the env (options it is made with, observation keys shown);
        an ask the benchmark does not support raises LayoutError naming the supported."""
        import copy

        self._servers_decl = (bench.raw or {}).get("servers")
        self._benchmark = bench.name
        self._protocol_values = {"init.seed": bench.init.get("seed"), "settle.steps": bench.settle_steps}
        self.layout = self._layout(self._asked_params())
        if self.layout is None:
            return bench
        out = copy.copy(bench)
        if self.layout.kwargs:
            out.kwargs = {**bench.kwargs, **self.layout.kwargs}
        keys = bench.observation.get("keys")
        if keys is not None:
            wanted = [k for k in self.layout.keys + self.layout.sources() if k not in keys]
            out.observation = {**bench.observation, "keys": [*keys, *wanted]}
        return out

    def _asked_params(self) -> dict[str, Any]:
        """What the server asks of the observation (a protocol whose server says so)."""
        return {}

    def _layout(self, params: dict[str, Any]) -> Layout | None:
        return layout_for(self._servers_decl, self.kind, params, self._benchmark, self._protocol_values)

    def describe(self) -> dict[str, Any]:
        """What the results record: the protocol, the URL and what the server said of itself
        (asked now, on slot 0's connection, if no connection has been made yet)."""
        if not self.server_info and not self._closed:
            try:
                self._submit(self._probe()).result(timeout=4 * self.timeout + _LOOP_GRACE_S)
            except SlotError as exc:
                log.warning("%s", exc)
            except concurrent.futures.TimeoutError:
                pass
        return {
            "kind": "server",
            "protocol": self.kind,
            "name": self.url,
            "url": self.url,
            "timeout_s": self.timeout,
            "server": _plain(self.server_info),
            "layout": None if self.layout is None else {"entries": self.layout.entries, "params": self.layout.params},
        }

    def close(self) -> None:
        """Closes every connection and stops the loop (bounded: a stuck server is abandoned)."""
        if self._closed:
            return
        # Episode ends still on their way go out first (each is bounded by `timeout`, but a
        # closing client waits for them only briefly).
        concurrent.futures.wait(list(self._pending), timeout=_CLOSE_TIMEOUT_S * 2)
        try:
            self._submit(self._close_all()).result(timeout=_CLOSE_TIMEOUT_S * 2 + 1)
        except Exception:
            pass
        self._closed = True
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=2)
        if not self._thread.is_alive() and not self._loop.is_running():
            self._loop.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            try:
                self.close()
            except Exception:
                pass  # at interpreter exit the loop's thread may be gone already

    # -- what a protocol implements -------------------------------------------------------

    async def _hello(self, ws: Any) -> dict[str, Any]:
        """The handshake after connecting: returns what the server said of itself."""
        raise NotImplementedError

    async def _begin(self, ws: Any, episode: Episode) -> None:
        """Tells the server an episode starts (nothing, for a protocol without episodes)."""

    async def _ask(self, ws: Any, request: Request) -> np.ndarray:
        """Sends one request and returns its action (or chunk); raises SlotError."""
        raise NotImplementedError

    async def _finish(self, ws: Any, episode: Episode, result: dict[str, Any]) -> None:
        """Tells the server the episode ended."""

    # -- on the loop ----------------------------------------------------------------------

    def _submit(self, coro) -> concurrent.futures.Future:
        if self._closed:
            coro.close()
            raise PolicyError(f"the {self.kind} client for {self.url} is closed")
        future = asyncio.run_coroutine_threadsafe(coro, self._loop)
        self._pending.add(future)
        future.add_done_callback(self._pending.discard)
        return future

    def _link(self, slot: int) -> _Link:
        link = self._links.get(slot)
        if link is None:
            link = self._links[slot] = _Link()
        return link

    async def _connect(self, link: _Link) -> None:
        if link.ws is not None:
            return
        from websockets.asyncio.client import connect

        try:
            ws = await asyncio.wait_for(
                connect(
                    self.url,
                    compression=None,
                    max_size=None,
                    # A server holding its GIL through a long model call must not be dropped.
                    ping_interval=None,
                    open_timeout=self.timeout,
                    close_timeout=_CLOSE_TIMEOUT_S,
                ),
                self.timeout,
            )
        except (asyncio.TimeoutError, TimeoutError):
            raise SlotError(
                f"connecting to the {self.kind} server at {self.url} took over {self.timeout:g} s"
            ) from None
        except Exception as exc:
            raise SlotError(f"could not connect to the {self.kind} server at {self.url}: {exc}") from None
        try:
            self.server_info = await asyncio.wait_for(self._hello(ws), self.timeout)
        except BaseException as exc:
            await _abandon(ws)
            if isinstance(exc, (asyncio.TimeoutError, TimeoutError)):
                raise SlotError(
                    f"the {self.kind} server at {self.url} did not complete its handshake within {self.timeout:g} s"
                ) from None
            raise _slot_error(exc, self, "its handshake") from None
        link.ws = ws

    async def _probe(self) -> None:
        link = self._link(0)
        async with link.lock:
            await self._connect(link)

    async def _drop(self, link: _Link) -> None:
        ws, link.ws = link.ws, None
        if ws is not None:
            await _abandon(ws)

    async def _start(self, slot: int, episode: Episode) -> None:
        link = self._link(slot)
        async with link.lock:
            link.episode, link.start_error = episode, None
            try:
                await self._connect(link)
                await asyncio.wait_for(self._begin(link.ws, episode), self.timeout)
            except BaseException as exc:
                link.start_error = str(_slot_error(exc, self, f"the start of episode {episode.key}"))
                await self._drop(link)

    async def _act(self, requests: list[Request]) -> list[Any]:
        return await asyncio.gather(*(self._act_one(r) for r in requests))

    async def _act_one(self, request: Request) -> Any:
        link = self._link(request.slot)
        async with link.lock:
            if link.episode != request.episode:
                # A runner that did not call start: begin the episode here.
                link.episode, link.start_error = request.episode, None
                try:
                    await self._connect(link)
                    await asyncio.wait_for(self._begin(link.ws, request.episode), self.timeout)
                except BaseException as exc:
                    link.start_error = str(
                        _slot_error(exc, self, f"the start of episode {request.episode.key}")
                    )
                    await self._drop(link)
            if link.start_error is not None:
                return SlotError(link.start_error)
            where = f"episode {request.episode.key} at step {request.step}"
            try:
                return await asyncio.wait_for(self._ask(link.ws, request), self.timeout)
            except (asyncio.TimeoutError, TimeoutError):
                error = SlotError(
                    f"the {self.kind} server at {self.url} sent no action within {self.timeout:g} s "
                    f"(--policy-timeout; {where})"
                )
            except BaseException as exc:
                if isinstance(exc, asyncio.CancelledError):
                    raise
                error = _slot_error(exc, self, where)
            # The connection's state is unknown now (a late answer may still come): drop it,
            # and fail the rest of the episode without asking again.
            await self._drop(link)
            link.start_error = str(error)
            return error

    async def _end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        link = self._link(slot)
        async with link.lock:
            if link.episode != episode:
                return
            link.episode = None
            if link.ws is None or link.start_error is not None:
                link.start_error = None
                return
            try:
                await asyncio.wait_for(self._finish(link.ws, episode, result), self.timeout)
            except BaseException as exc:
                if isinstance(exc, asyncio.CancelledError):
                    raise
                log.warning("%s: ending episode %s failed: %s", self.url, episode.key, exc)
                await self._drop(link)

    async def _close_all(self) -> None:
        for task in asyncio.all_tasks():
            if task is not asyncio.current_task():
                task.cancel()
        await asyncio.gather(*(self._drop(link) for link in self._links.values()))


async def _abandon(ws: Any) -> None:
    try:
        await asyncio.wait_for(ws.close(), _CLOSE_TIMEOUT_S)
    except BaseException:
        pass


def _slot_error(exc: BaseException, policy: ServerPolicy, where: str) -> SlotError:
    """A slot's failure with its cause in words: a closed connection names its code and reason."""
    if isinstance(exc, SlotError):
        return exc
    if isinstance(exc, LayoutError):
        return SlotError(f"{exc} ({where})")
    from websockets.exceptions import ConnectionClosed

    if isinstance(exc, ConnectionClosed):
        frame = exc.rcvd
        how = f" (code {frame.code}{': ' + frame.reason if frame.reason else ''})" if frame else ""
        return SlotError(
            f"the {policy.kind} server at {policy.url} closed the connection{how} during {where}"
        )
    if isinstance(exc, (asyncio.TimeoutError, TimeoutError)):
        return SlotError(
            f"the {policy.kind} server at {policy.url} did not answer within {policy.timeout:g} s during {where}"
        )
    return SlotError(
        f"{type(exc).__name__} talking to the {policy.kind} server at {policy.url} during {where}: {exc}"
    )


def _plain(value: Any, depth: int = 0) -> Any:
    """`value` as JSON can hold it (what a server says of itself goes into the results)."""
    if depth > 6:
        return repr(value)[:200]
    if isinstance(value, dict):
        return {
            str(k.decode() if isinstance(k, bytes) else k): _plain(v, depth + 1) for k, v in value.items()
        }
    if isinstance(value, (list, tuple)):
        return [_plain(v, depth + 1) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist() if value.size <= 64 else f"<array {value.dtype} {list(value.shape)}>"
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace") if len(value) <= 200 else f"<{len(value)} bytes>"
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)[:200]


def checked_action(value: Any, what: str) -> np.ndarray:
    """A server's action as the runner takes it: a finite-or-not numeric array of shape
    `(action_dim,)` or a chunk `(k, action_dim)`; else SlotError naming what came and what
    was expected. (The action space itself is the runner's check.)"""
    expected = f"{what} as a numeric array of shape (action_dim,) or an action chunk (k, action_dim)"
    if value is None:
        raise SlotError(f"the answer had no action; expected {expected}")
    try:
        array = np.asarray(value)
    except Exception:
        raise SlotError(f"the answer's action is {type(value).__name__}; expected {expected}") from None
    if array.dtype.kind not in "biuf":
        raise SlotError(f"the answer's action has dtype {array.dtype} ({_brief(value)}); expected {expected}")
    if array.ndim not in (1, 2) or array.size == 0:
        raise SlotError(f"the answer's action has shape {array.shape}; expected {expected}")
    return array


def _brief(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def wire_observation(observation: Any, fields: dict[str, str] | None, default_key: Any) -> dict[str, Any]:
    """The observation laid out as a server reads it. `fields` maps a wire path (nested
    dicts joined by `.`: `images.agentview`) to an observation key (`""`: the whole
    observation, when it is an array); without it, `default_key(name, array)` names each
    entry's wire path."""
    out: dict[str, Any] = {}
    if fields is not None:
        for path, key in fields.items():
            if key == "":
                value = observation
            elif isinstance(observation, dict) and key in observation:
                value = observation[key]
            else:
                valid = sorted(observation) if isinstance(observation, dict) else ['""']
                raise SlotError(
                    f"the observation has no key {key!r} (for the server's {path!r}); it has {valid}"
                )
            _put(out, path, value)
        return out
    items = observation.items() if isinstance(observation, dict) else [("", observation)]
    for name, value in items:
        _put(out, default_key(name, value), value)
    return out


def _put(out: dict[str, Any], path: str, value: Any) -> None:
    *parents, leaf = path.split(".")
    for part in parents:
        out = out.setdefault(part, {})
    out[leaf] = value


def is_image(value: Any) -> bool:
    """An HxWxC uint8 array (C in 1, 3, 4): what both protocols treat as a camera image."""
    return (
        isinstance(value, np.ndarray)
        and value.ndim == 3
        and value.dtype == np.uint8
        and value.shape[2] in (1, 3, 4)
    )
