"""`call`, `get_attr` and `set_attr` of `envhub.AsyncVectorEnv`: a side channel to the envs.

The data plane carries only reset, step and render. Gymnasium's `AsyncVectorEnv` also calls
any method or reads any attribute of its envs through its pipes, so each `env_fns` worker
answers such requests on a Unix socket in a private folder of the client
(`multiprocessing.connection`, with an auth key), from a thread: it runs only while the
client waits for the answer, so never while the worker steps (the client refuses a call
while a `send` is pending). Rare and small, as in Gymnasium, so pickling is fine here.
"""

from __future__ import annotations

import os
import threading
from multiprocessing import AuthenticationError
from multiprocessing.connection import Client, Connection, Listener
from typing import Any

#: Names Gymnasium refuses to `call` (they have their own methods).
RESERVED = ("reset", "step", "close", "_setattr", "_check_spaces")

# This worker's envs by session index, and whether its listener runs.
_ENVS: dict[int, Any] = {}
_STARTED: list[object] = []  # the listener's address, once it runs


def serve(folder: str, authkey: bytes, index: int, env: Any) -> None:
    """Makes env `index` (the user's env) reachable; starts this worker's listener once."""
    _ENVS[index] = env
    if _STARTED:
        return
    listener = Listener(os.path.join(folder, f"worker-{os.getpid()}.sock"), "AF_UNIX", authkey=authkey)
    _STARTED.append(listener.address)
    threading.Thread(target=_accept, args=(listener,), name="envhub-calls", daemon=True).start()


def _accept(listener: Listener) -> None:
    while True:
        try:
            conn = listener.accept()
        except AuthenticationError:  # not our client: keep serving ours
            continue
        except OSError:  # the socket is gone: nothing more to serve
            return
        threading.Thread(target=_answer, args=(conn,), daemon=True).start()


def _call(env: Any, name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    # As Gymnasium's `_async_worker`.
    if name in RESERVED:
        raise ValueError(f"Trying to call function `{name}` with `call`, use `{name}` directly instead.")
    attr = env.get_wrapper_attr(name) if hasattr(env, "get_wrapper_attr") else getattr(env, name)
    return attr(*args, **kwargs) if callable(attr) else attr


def _set(env: Any, name: str, value: Any) -> None:
    if hasattr(env, "set_wrapper_attr"):
        env.set_wrapper_attr(name, value)
    else:
        setattr(env, name, value)


def _answer(conn: Connection) -> None:
    with conn:
        while True:
            try:
                kind, name, args, kwargs = conn.recv()
            except (EOFError, OSError):
                return
            try:
                ids = sorted(_ENVS)
                if kind == "envs":
                    result: Any = ids
                elif kind == "call":
                    result = [_call(_ENVS[i], name, args, kwargs) for i in ids]
                else:  # "set": args holds one value per env index
                    for i in ids:
                        _set(_ENVS[i], name, args[i])
                    result = [None] * len(ids)
                conn.send(("ok", result))
            except Exception as e:
                try:
                    conn.send(("error", e))
                except Exception:
                    conn.send(("error", RuntimeError(f"{type(e).__name__}: {e}")))


class Calls:
    """The client's end: one connection per worker, opened on first use."""

    def __init__(self, folder: str, authkey: bytes, num_envs: int, timeout: float | None) -> None:
        self.folder, self.authkey, self.num_envs, self.timeout = folder, authkey, num_envs, timeout
        self._workers: list[tuple[list[int], Connection]] | None = None

    def _connect(self) -> list[tuple[list[int], Connection]]:
        if self._workers is None:
            workers = []
            for name in sorted(os.listdir(self.folder)):
                conn = Client(os.path.join(self.folder, name), "AF_UNIX", authkey=self.authkey)
                workers.append((self._ask(conn, ("envs", "", (), {})), conn))
            found = sorted(i for ids, _ in workers for i in ids)
            if found != list(range(self.num_envs)):
                raise RuntimeError(f"the workers' call sockets reach envs {found}, not all {self.num_envs}")
            self._workers = workers
        return self._workers

    def _ask(self, conn: Connection, request: tuple[Any, ...]) -> Any:
        conn.send(request)
        if not conn.poll(self.timeout):
            raise TimeoutError(f"no answer to `{request[0]}({request[1]!r})` within {self.timeout} s")
        status, value = conn.recv()
        if status == "error":
            raise value
        return value

    def call(self, name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> tuple[Any, ...]:
        """`name` of every env (called with the arguments when it is callable), in env order."""
        out: dict[int, Any] = {}
        for ids, conn in self._connect():
            answers = self._ask(conn, ("call", name, args, kwargs))
            # Checked by hand: `zip(strict=True)` is 3.10's, and this module runs in workers
            # down to 3.9 (docs/design/architecture.md).
            if len(answers) != len(ids):
                raise RuntimeError(f"a worker answered `{name}` for {len(answers)} envs, not its {len(ids)}")
            out.update(zip(ids, answers))
        return tuple(out[i] for i in range(self.num_envs))

    def set(self, name: str, values: list[Any]) -> None:
        """Sets `name` of env `i` to `values[i]`."""
        for ids, conn in self._connect():
            self._ask(conn, ("set", name, {i: values[i] for i in ids}, {}))

    def close(self) -> None:
        for _, conn in self._workers or []:
            conn.close()
        self._workers = None
