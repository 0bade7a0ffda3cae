"""`envhub.AsyncVectorEnv`: Gymnasium's `AsyncVectorEnv`, served by envhub's workers.

Same constructor and results as `gymnasium.vector.AsyncVectorEnv(env_fns, ...)`, so changing
one import moves a training script onto envhub's worker processes and shared-memory data
plane. The factories are cloudpickled into a private temporary file, and the session is one
of the built-in `env_fns` adapter (`envhub.worker.hosted.env_fns`) with that file as its env id (no
registry entry, so a hub daemon serves it as well); each worker loads the file and builds env
`i` with factory `i`. The file is removed once the workers have built their envs.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium.spaces import Space
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_differing_spaces, batch_space

from ..wire.autoreset import autoreset_mode as _autoreset_mode
from ..wire.calls import Calls
from ..wire.cores import usable_cores
from ..wire.errors import InvalidConfigError, InvalidStateError, MakeError
from ..wire.pickled import decode_info, wrap
from ..worker.hosted.env_fns import FRAMEWORK, write_payload
from .infos import flat_infos
from .vector import VectorEnv
from .vector import _GymnasiumBatch as _Batch

__all__ = ["AsyncVectorEnv"]


def _pickle_factories(env_fns: Sequence[Callable[[], Any]]) -> bytes:
    import cloudpickle

    try:
        return cloudpickle.dumps(list(env_fns))
    except Exception as e:
        for i, fn in enumerate(env_fns):  # name the factory that cannot travel
            try:
                cloudpickle.dumps(fn)
            except Exception as e_i:
                raise InvalidConfigError(
                    f"env factory {i} ({getattr(fn, '__qualname__', type(fn).__name__)}) cannot be pickled "
                    f"with cloudpickle, so it cannot reach envhub's worker processes: {type(e_i).__name__}: {e_i}\n"
                    "hint: build unpicklable objects (locks, open files, sockets, simulators) inside the "
                    "factory rather than capturing them"
                ) from e_i
        raise InvalidConfigError(
            f"the env factories cannot be pickled with cloudpickle: {type(e).__name__}: {e}"
        ) from e


class AsyncVectorEnv(VectorEnv):
    """`gymnasium.vector.AsyncVectorEnv` on envhub: `env_fns[i]()` builds env `i` in an
    envhub worker process, and results arrive through shared memory.

    Same seeds give the same observations, rewards, terminations, truncations and infos as
    Gymnasium's (`autoreset_mode` included; actions of the action space's dtype reach the
    env unchanged, others are cast to it). The worker processes are envhub's: `num_workers`
    (alias `workers`) sets how many (default: one per core, at most one per env; each hosts
    a contiguous slice of the envs). Of Gymnasium's options, `shared_memory`, `copy`,
    `context` and `daemon` have no effect — results always travel through shared memory,
    returned arrays are never overwritten later (as copies would be), and workers always
    exit with this process; a custom `worker` cannot apply and is refused; `max_concurrency`
    caps the default number of workers.

    `call`, `get_attr`, `set_attr` and `render` reach the envs in their workers as in
    Gymnasium (through a side channel: the data plane carries only reset and step).
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], Any]],
        shared_memory: bool = True,
        copy: bool = True,
        context: str | None = None,
        daemon: bool = True,
        worker: Callable[..., None] | None = None,
        observation_mode: str | Space | tuple[Space, Space] = "same",
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_concurrency: int | None = None,
        *,
        num_workers: int | None = None,
        workers: int | None = None,
        step_timeout: float | None = None,
    ) -> None:
        if worker is not None:
            raise InvalidConfigError(
                "`worker` (a custom Gymnasium worker function) cannot apply: envhub's workers run the "
                "envs in their own serve loop\nhint: leave `worker` out, or use "
                "gymnasium.vector.AsyncVectorEnv for a custom worker"
            )
        if context is not None:
            multiprocessing.get_context(context)  # an invalid name fails as in Gymnasium
        if num_workers is not None and workers is not None and num_workers != workers:
            raise InvalidConfigError(f"`num_workers={num_workers}` and `workers={workers}` disagree; pass one")
        num_workers = num_workers if num_workers is not None else workers
        env_fns = list(env_fns)
        if not env_fns:
            raise InvalidConfigError("`env_fns` is empty; pass one env factory per env")
        for i, fn in enumerate(env_fns):
            if not callable(fn):
                raise InvalidConfigError(
                    f"env factory {i} is a {type(fn).__name__}, not a callable that returns an env"
                )
        if max_concurrency is not None:
            if isinstance(max_concurrency, bool) or not isinstance(max_concurrency, int | np.integer):
                raise InvalidConfigError(f"`max_concurrency` must be an integer or None, got {max_concurrency!r}")
            if max_concurrency < 1:
                raise InvalidConfigError(f"`max_concurrency` must be positive or None, got {max_concurrency}")
            if num_workers is None:
                num_workers = min(int(max_concurrency), len(env_fns), usable_cores())
        mode = _autoreset_mode(autoreset_mode)  # Gymnasium's values and envhub's names

        # As Gymnasium does: the first env, built here, gives the metadata and spaces.
        dummy = env_fns[0]()
        try:
            metadata = dict(getattr(dummy, "metadata", {}) or {})
            render_mode = getattr(dummy, "render_mode", None)
            single_action_space = dummy.action_space
            if isinstance(observation_mode, tuple) and len(observation_mode) == 2:
                observation_space, single_observation_space = observation_mode
            elif observation_mode == "same":
                single_observation_space = dummy.observation_space
                observation_space = batch_space(single_observation_space, len(env_fns))
            elif observation_mode == "different":
                spaces = [fn().observation_space for fn in env_fns]
                single_observation_space = spaces[0]
                observation_space = batch_differing_spaces(spaces)
            else:
                raise InvalidConfigError(
                    f"invalid `observation_mode` {observation_mode!r}; valid: 'same', 'different', or a "
                    "(batched observation space, single observation space) tuple"
                )
        finally:
            dummy.close()

        folder = tempfile.mkdtemp(prefix="envhub-env-fns-")  # private (mode 0700)
        # The workers' sockets for `call`, `get_attr` and `set_attr`: kept until `close`.
        self._calls_folder = tempfile.mkdtemp(prefix="envhub-calls-")
        authkey = os.urandom(32)
        try:
            payload = os.path.join(folder, "env_fns.pkl")
            write_payload(payload, _pickle_factories(env_fns), (self._calls_folder, authkey))
            super().__init__(
                payload,  # the `env_fns` adapter's env id: no registry entry, so a daemon serves it too
                len(env_fns),
                num_workers,
                mode,
                # Only rgb_array frames travel; other modes draw in the worker, if anywhere.
                render_mode=render_mode if render_mode == "rgb_array" else None,
                step_timeout=step_timeout,
                _adapter=FRAMEWORK,
            )
        except MakeError as e:  # name the drop-in rather than its temporary file
            shutil.rmtree(self._calls_folder, ignore_errors=True)
            raise MakeError(
                str(e).replace(f"cannot make `{payload}` with adapter `{FRAMEWORK}`", "a worker cannot build its envs")
            ) from None
        except BaseException:
            shutil.rmtree(self._calls_folder, ignore_errors=True)
            raise
        finally:
            shutil.rmtree(folder, ignore_errors=True)  # the workers have loaded it

        self.env_fns = env_fns
        self.shared_memory = shared_memory
        self.copy = copy
        self.context = context
        self.daemon = daemon
        self.worker = worker
        self.observation_mode = observation_mode
        self.autoreset_mode = mode
        self.max_concurrency = max_concurrency
        self.metadata = {**metadata, "autoreset_mode": mode}
        self.render_mode = render_mode
        self.single_action_space = single_action_space
        self.action_space = batch_space(single_action_space, self.num_envs)
        self.single_observation_space = single_observation_space
        self.observation_space = observation_space
        self._pending: Any = None
        self._calls = Calls(self._calls_folder, authkey, self.num_envs, step_timeout)

    # Gymnasium's reset and step, with options and infos carried whole --------------------

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """As Gymnasium's: env `i` seeded with `seed + i` (or `seed[i]`), `options` given to
        every env reset (`options["reset_mask"]`: only the envs where it is true)."""
        if options is None:
            return super().reset(seed=seed)
        options = dict(options)
        mask = options.pop("reset_mask", None)
        if mask is not None:
            if not isinstance(mask, np.ndarray):
                raise TypeError(f"`options['reset_mask']` must be a numpy array, got {type(mask)}")
            if not np.any(mask):
                raise ValueError(f"`options['reset_mask']` must contain at least one True value, got {mask}")
        carried: dict[str, Any] = dict(wrap(options))
        if mask is not None:
            carried["reset_mask"] = mask
        return super().reset(seed=seed, options=carried)

    def reset_async(self, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None) -> None:
        """Records a reset for `reset_wait` (which runs it)."""
        self._expect_none_pending("reset_async")
        self._pending = ("reset", seed, options)

    def reset_wait(self, timeout: float | None = None) -> tuple[Any, dict[str, Any]]:
        """Runs the reset `reset_async` recorded (`timeout` is the session's `step_timeout`)."""
        kind, seed, options = self._take_pending("reset")
        return self.reset(seed=seed, options=options)

    def step_async(self, actions: Any) -> None:
        """Records the actions for `step_wait` (which steps the envs)."""
        self._expect_none_pending("step_async")
        self._pending = ("step", actions, None)

    def step_wait(self, timeout: float | None = None) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Steps the envs with the actions `step_async` recorded."""
        _, actions, _ = self._take_pending("step")
        return self.step(actions)

    def _expect_none_pending(self, call: str) -> None:
        if self._pending is not None:
            raise InvalidStateError(f"`{call}` while a `{self._pending[0]}_async` awaits its `{self._pending[0]}_wait`")

    def _take_pending(self, kind: str) -> Any:
        if self._pending is None or self._pending[0] != kind:
            raise InvalidStateError(f"`{kind}_wait` without a prior `{kind}_async`")
        pending, self._pending = self._pending, None
        return pending

    def _info(
        self, infos: list[dict[str, Any]] | None, final: list[Any] | None, n: int, cols: Any = None
    ) -> dict[str, Any]:
        if cols is not None:
            ready, infos = self._with_rows(infos, final, n, cols)
            if ready is not None:
                return ready
        # Gymnasium's own batching of each env's info, once unwrapped; same_step infos are
        # rebuilt as its worker builds them.
        if final is None and infos is not None:
            flat = flat_infos([decode_info(info) if info else None for info in infos], n)
            if flat is not None:
                return flat
        out: dict[str, Any] = {}
        batch = _Batch(n)
        for k in range(n):
            raw = dict(infos[k]) if infos is not None and infos[k] else {}
            final_info = raw.pop("final_info", None)  # the serve loop's, as JSON text
            env_info = decode_info(raw)
            if final is not None and final[k] is not None:
                if isinstance(final_info, str):
                    final_info = json.loads(final_info)
                env_info = {
                    "final_info": decode_info(final_info),
                    "final_obs": self._codec.obs_from_bytes(final[k]),
                    **env_info,
                }
            if env_info:
                out = batch._add_info(out, env_info, k)
        return out

    # Calls to the envs, through the workers' side channel (`envhub._calls`) -----------------

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Calls method `name` of every env with the arguments (or reads attribute `name`),
        as Gymnasium's: one result per env. An exception in an env is raised here."""
        return self._calls_of_idle("call").call(name, args, kwargs)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Attribute `name` of every env."""
        return self.call(name)

    def set_attr(self, name: str, values: list[Any] | tuple[Any, ...] | Any) -> None:
        """Sets attribute `name` of every env: to `values[i]` for env `i` given a list or
        tuple (one per env), else to `values` for all."""
        if not isinstance(values, list | tuple):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(f"values must be a list of length {self.num_envs}, got {len(values)}")
        self._calls_of_idle("set_attr").set(name, list(values))

    def render(self) -> tuple[Any, ...] | None:
        """Every env's `render()`, as Gymnasium's (`call("render")`)."""
        return self.call("render")

    def _calls_of_idle(self, what: str) -> Calls:
        if self.closed:
            raise InvalidStateError(f"`{what}` on a closed envhub.AsyncVectorEnv")
        if self._sent.any():
            raise InvalidStateError(f"`{what}` while envs stepped by `send` await their `recv`")
        return self._calls

    def close_extras(self, **kwargs: Any) -> None:
        """Stops the workers and removes their call sockets."""
        calls = getattr(self, "_calls", None)
        if calls is not None:
            calls.close()
        super().close_extras(**kwargs)
        folder = getattr(self, "_calls_folder", None)
        if folder is not None:  # after the workers, which remove their own sockets as they exit
            shutil.rmtree(folder, ignore_errors=True)

    def __repr__(self) -> str:
        return f"envhub.AsyncVectorEnv(num_envs={self.num_envs}, num_workers={self.num_workers})"
