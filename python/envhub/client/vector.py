"""`envhub.VectorEnv`: a batch of envs in worker processes, as a `gymnasium.vector.VectorEnv`."""

from __future__ import annotations

import json
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from ..wire import info_tree as _info_tree
from ..wire import spaces as _spaces
from ..wire.autoreset import RUST_MODES as _RUST_MODES
from ..wire.autoreset import autoreset_mode as _autoreset_mode
from ..wire.config import EnvConfig, to_json
from ..wire.errors import InvalidActionError, InvalidConfigError, InvalidStateError
from ..wire.info_schema import INFO_ROW_BYTES
from .column_reader import ColumnReader
from .infos import flat_infos
from .session import HubsArg, RegistryArg, check_seed, fps_metadata, start

__all__ = ["VectorEnv"]


def _add_info(infos: dict[str, Any], env_info: dict[str, Any], k: int, n: int) -> dict[str, Any]:
    """Gymnasium's vector info layout of env `k`'s info added to `infos`: Gymnasium's own
    `VectorEnv._add_info` (nested dicts recursively, `final_obs` an object array, `np.bool_`,
    text and lists in object arrays, ragged values kept as they are), so a step's infos are
    batched as `SyncVectorEnv` batches them, whatever Gymnasium version runs here."""
    return _GymnasiumBatch(n)._add_info(infos, env_info, k)


class _GymnasiumBatch:
    """What Gymnasium's `VectorEnv._add_info` reads of `self`: the batch's size."""

    _add_info = gymnasium.vector.VectorEnv._add_info

    def __init__(self, n: int) -> None:
        self.num_envs = n


class VectorEnv(gymnasium.vector.VectorEnv[Any, Any, np.ndarray]):
    """`num_envs` envs of registry entry `registry_id`, spread over `num_workers` worker
    processes (default: one per core, at most one per env).

    Observations, rewards and flags are writeable numpy arrays viewing one shared-memory
    block that every worker writes its envs' rows into: no copy, whatever the number of
    workers. An array you keep stays valid and unchanged (its block is not reused while it
    lives); past the session's memory cap (`pool_bytes`, 512 MiB by default) results are
    copied rather than waited for.

    `autoreset_mode` is Gymnasium's: `next_step` (default), `same_step` (`final_obs` and
    `final_info` in the step's info), or `disabled` (reset finished envs yourself with
    `reset(options={"reset_mask": mask})`).

    EnvPool's asynchronous contract with `batch_size=M` (1 <= M <= `num_envs`):
    `async_reset()`, then `recv()` returns exactly the first M envs to finish (their ids in
    `info["env_id"]`, in the order they finished) and `send(actions, env_id)` steps envs
    `recv` handed out. Without `batch_size`, `send`/`recv` are worker-granular: `recv`
    returns the envs of the first workers to answer.
    """

    def __init__(
        self,
        registry_id: str,
        num_envs: int = 1,
        num_workers: int | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        *,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        seed: int | None = None,
        asset_path: str | None = None,
        registry: RegistryArg = None,
        step_timeout: float | None = None,
        restart_on_crash: bool = False,
        pool_bytes: int | None = None,
        strict_actions: bool = False,
        hubs: HubsArg = None,
        batch_size: int | None = None,
        remote_lanes: int = 1,
        _adapter: str | None = None,
        _info_row_bytes: int = INFO_ROW_BYTES,
        **extra: Any,
    ) -> None:
        # `_adapter` (private): `registry_id` is that adapter's env id, no registry entry.
        # `_info_row_bytes` (private): typed info columns per env in the slots, which the hub
        # keeps only where a Python worker writes them (0: none).
        mode = _autoreset_mode(autoreset_mode)
        config = EnvConfig(
            render_mode=render_mode,
            seed=seed,
            max_episode_steps=max_episode_steps,
            num_envs=num_envs,
            asset_path=asset_path,
            extra=extra,
            workers=num_workers,
            autoreset_mode=_RUST_MODES[mode],
            strict_actions=strict_actions,
        )
        if isinstance(remote_lanes, bool) or not isinstance(remote_lanes, int | np.integer) or remote_lanes < 1:
            raise InvalidConfigError(f"remote_lanes must be a positive integer, got {remote_lanes!r}")
        self._session = start(
            registry_id,
            config,
            registry,
            step_timeout,
            restart_on_crash,
            pool_bytes,
            _adapter,
            hubs,
            _info_row_bytes,
            int(remote_lanes),
        )
        row_bytes = int(self._session.info_row_bytes)
        self._columns = ColumnReader(row_bytes, self._session.info_schema) if row_bytes else None
        s = self._session
        self.registry_id = registry_id
        self.num_envs = int(s.num_envs)
        #: Where the envs run: `(hub, first env, end)` per run; `"local"` is this machine.
        self.placement: list[tuple[str, int, int]] = [tuple(p) for p in s.placement]
        self._codec = _spaces.Codec(
            s.observation_space_json, s.obs_leaves_json, s.action_space_json, s.action_leaves_json, self.num_envs
        )
        self.single_observation_space = _spaces.to_gymnasium(json.loads(s.observation_space_json))
        self.single_action_space = _spaces.to_gymnasium(json.loads(s.action_space_json))
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": [render_mode] if render_mode else [],
            **fps_metadata(s),
        }
        self.render_mode = render_mode
        self._last_obs: np.ndarray | None = None
        self._obs_bytes_copied = 0  # by this class (masked resets, folding `recv`s)
        # Rows `recv` returned since `_last_obs` (env ids, raw rows), merged into a copy only
        # when a masked reset needs the batch's latest observations.
        self._received: list[tuple[np.ndarray, np.ndarray]] = []
        # `seed=` seeds the first reset that is not given one (env `i` with `seed + i`).
        self._first_seed = check_seed(seed)
        self._sent = np.zeros(self.num_envs, dtype=np.bool_)
        if batch_size is not None:
            if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer):
                self.close()
                raise InvalidConfigError(f"batch_size must be an integer, got {batch_size!r}")
            try:
                s.set_batch_size(int(batch_size))
            except BaseException:
                self.close()
                raise

    # Lock-step ------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Resets every env (env `i` seeded with `seed + i`, or `seed[i]` from a list); with
        `options={"reset_mask": mask}` only the envs where `mask` is true."""
        seeds, first = self._seeds(seed)
        super().reset(seed=first)
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is not None:
            mask = np.asarray(mask)
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise InvalidConfigError(
                    f"reset_mask must be a bool array of shape ({self.num_envs},), got {mask.dtype} {mask.shape}"
                )
            if self._last_obs is None and not mask.all():
                raise InvalidStateError("reset with `reset_mask` needs a full reset first")
        raw, _, _, _, infos, _, cols = self._session.reset(
            seeds, None if mask is None else mask.tolist(), to_json(options) if options else None
        )
        if type(cols) is dict:  # every env's info in its row, laid out by the session
            self._last_obs = raw
            self._received.clear()
            self._sent[:] = False
            return self._codec.obs(raw), cols
        if mask is not None and not mask.all():
            self._keep_latest(raw, ~mask)
            if infos is not None:
                infos = [info if m else {} for info, m in zip(infos, mask, strict=True)]
        self._last_obs = raw
        self._received.clear()
        self._sent[:] = False
        return self._codec.obs(raw), self._info(infos, None, self.num_envs, cols)

    def _seeds(self, seed: int | list[int | None] | None) -> tuple[list[int | None], int | None]:
        """One seed per env for a reset (env `i` gets `seed + i`, or `seed[i]` from a list;
        the `seed` given at make if none), and the first."""
        if isinstance(seed, list | tuple | np.ndarray):
            if len(seed) != self.num_envs:
                raise InvalidConfigError(f"got {len(seed)} seeds for {self.num_envs} envs; pass one per env")
            seeds = [check_seed(s) for s in seed]
            first = seeds[0]
        else:
            first = check_seed(seed)
            if first is None and self._first_seed is not None:
                first = self._first_seed
            seeds = [None if first is None else first + i for i in range(self.num_envs)]
        self._first_seed = None
        return seeds, first

    def _keep_latest(self, raw: np.ndarray, keep: np.ndarray) -> None:
        """Writes the latest observation of each env in `keep` into its row of `raw` (the
        results of a masked reset, which hold nothing for them): only those rows are
        copied, and the reset envs' rows stay where the workers wrote them."""
        last: np.ndarray = self._last_obs  # type: ignore[assignment]
        raw[keep] = last[keep]
        for ids, rows in self._received:
            sel = keep[ids]
            raw[ids[sel]] = rows[sel]
        self._obs_bytes_copied += int(keep.sum()) * (raw.nbytes // max(len(raw), 1))

    def _latest_obs(self) -> np.ndarray:
        """A copy of every env's latest raw observation: the last full batch, with the rows
        `recv` returned since then."""
        merged = self._last_obs.copy()  # type: ignore[union-attr]
        for ids, rows in self._received:
            merged[ids] = rows
        self._obs_bytes_copied += merged.nbytes + sum(rows.nbytes for _, rows in self._received)
        return merged

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Steps every env with its action (an array of shape `action_space.shape`)."""
        raw, rewards, terminated, truncated, infos, final, cols = self._session.step(self._codec.actions(actions))
        self._last_obs = raw
        self._received.clear()
        if type(cols) is dict:  # every env's info in its row, laid out by the session
            return self._codec.obs(raw), rewards, terminated, truncated, cols
        if infos is None and final is None and cols is None:
            return self._codec.obs(raw), rewards, terminated, truncated, {}
        return self._codec.obs(raw), rewards, terminated, truncated, self._info(infos, final, self.num_envs, cols)

    # EnvPool-style asynchronous stepping ---------------------------------------------------

    @property
    def batch_size(self) -> int | None:
        """EnvPool's `batch_size`: how many envs `recv` returns (`None`: the envs of the
        first workers to answer)."""
        return self._session.batch_size

    def async_reset(self, *, seed: int | list[int | None] | None = None) -> None:
        """EnvPool's `async_reset`: resets every env without waiting (env `i` seeded with
        `seed + i`, or `seed[i]` from a list; the `seed` given to `make_vec` if none);
        `recv` returns them `batch_size` at a time. Results not received yet are dropped.
        Without `batch_size`, this sets it to `num_envs`."""
        seeds, first = self._seeds(seed)
        super().reset(seed=first)
        self._session.async_reset(seeds)
        self._last_obs = None
        self._received.clear()
        self._sent[:] = True

    def _checked_env_ids(self, env_ids: Any) -> np.ndarray:
        """`env_ids` as a flat integer array of distinct envs of this session, or an error
        naming what is wrong and the valid range."""
        ids = np.asarray(env_ids).reshape(-1)
        if ids.dtype.kind not in "iu":
            raise InvalidActionError(f"env_ids must be integers, got {ids.dtype}")
        outside = ids[(ids < 0) | (ids >= self.num_envs)]
        if len(outside):
            raise InvalidActionError(
                f"env_ids {outside[:8].tolist()} are not envs of this session; valid: 0 to {self.num_envs - 1}"
            )
        if len(np.unique(ids)) != len(ids):
            raise InvalidActionError("env_ids must not repeat an env")
        return ids

    def send(self, actions: Any, env_id: Any = None, *, env_ids: Any = None) -> None:
        """Sends one action to each env in `env_id` (EnvPool's name; `env_ids` is the same)
        without waiting; all envs if `None`. With `batch_size`, pass the envs `recv` returned
        (`info["env_id"]`): an env whose worker is busy waits and goes out when it answers."""
        if env_ids is None:
            env_ids = env_id
        elif env_id is not None:
            raise InvalidActionError("pass `env_id` or `env_ids`, not both")
        ids = np.arange(self.num_envs) if env_ids is None else self._checked_env_ids(env_ids)
        a = self._codec.actions(actions, count=len(ids))
        self._session.send(a, ids.astype(np.int64).tolist())
        self._sent[ids] = True

    def send_reset(
        self, env_ids: Any, *, seed: list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> None:
        """Resets the envs in `env_ids` without waiting (env `env_ids[k]` seeded with
        `seed[k]`; `options` for all of them), while the session's other envs go on
        stepping; `recv` returns their first observations and reset infos as it returns
        stepped envs (rewards 0, not done). An env's episode is the same as after
        `reset(seed=..., options={..., "reset_mask": mask})` of it. Without `batch_size`
        only (`send`'s worker rule holds: an env whose worker has results out is refused)."""
        ids = self._checked_env_ids(env_ids)
        seeds = [None] * len(ids) if seed is None else [check_seed(s) for s in seed]
        if len(seeds) != len(ids):
            raise InvalidConfigError(f"got {len(seeds)} seeds for {len(ids)} envs; pass one per env id")
        if options and "reset_mask" in options:
            raise InvalidConfigError("send_reset resets the envs it names; leave `reset_mask` out")
        self._session.send_reset(ids.astype(np.int64).tolist(), seeds, to_json(options) if options else None)
        self._sent[ids] = True

    def recv(self) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Waits for the first workers to finish and returns the results of the envs they
        stepped; with `batch_size`, exactly that many envs, the first to finish.
        `info["env_id"]` says which envs they are."""
        # The session has taken announced schemas out of `infos` already, so an announcing
        # env left out below loses nothing.
        raw, rewards, terminated, truncated, infos, final, ids, cols = self._session.recv()
        keep = self._sent[ids]
        self._sent[ids] = False
        if not keep.all():
            raw, rewards, terminated, truncated, ids = (
                raw[keep],
                rewards[keep],
                terminated[keep],
                truncated[keep],
                ids[keep],
            )
            infos = None if infos is None else [i for i, k in zip(infos, keep, strict=True) if k]
            final = None if final is None else [f for f, k in zip(final, keep, strict=True) if k]
            cols = None if cols is None else cols[keep]
        if self._last_obs is not None and len(ids):
            self._received.append((ids, raw))
            if len(self._received) > 64:  # bounded: fold them into one batch
                self._last_obs, self._received = self._latest_obs(), []
        info = self._info(infos, final, len(ids), cols)
        info["env_id"] = ids
        return self._codec.obs(raw), rewards, terminated, truncated, info

    # ---------------------------------------------------------------------------------------

    def _with_rows(
        self, infos: list[dict[str, Any]] | None, final: list[Any] | None, n: int, cols: np.ndarray
    ) -> tuple[dict[str, Any] | None, list[dict[str, Any]] | None]:
        """The info columns `cols` (a `[n, row_bytes]` block) read: Gymnasium's vector info
        itself when every env's info is in its row under one schema and nothing else came
        (views of the rows), else None and each env's info as it travelled, with its row's
        values first where it has one (then any keys the session added, as a restart's)."""
        columns = self._columns
        ids = columns.ids(cols)  # type: ignore[union-attr]
        if final is None and infos is None:
            first = int(ids[0]) if n else 0
            if first and (ids == first).all():
                return columns.columns(cols, first), infos  # type: ignore[union-attr]
            if not ids.any():
                return {}, infos
        if ids.any():
            json_infos = infos if infos is not None else [None] * n
            infos = [
                {**columns.env_info(cols, k, int(ids[k])), **(json_infos[k] or {})}  # type: ignore[union-attr]
                if ids[k]
                else json_infos[k]
                for k in range(n)
            ]
        return None, infos

    def _info(
        self, infos: list[dict[str, Any]] | None, final: list[Any] | None, n: int, cols: Any = None
    ) -> dict[str, Any]:
        if cols is not None:
            ready, infos = self._with_rows(infos, final, n, cols)
            if ready is not None:
                return ready
        if final is None and infos is not None:
            flat = flat_infos(infos, n)
            if flat is not None:
                return flat
        # Env by env, an ended episode's final observation and info before the new one's
        # info, as Gymnasium's `SyncVectorEnv` adds them (so the keys come in its order).
        out: dict[str, Any] = {}
        for k in range(n):
            info = infos[k] if infos is not None else None
            data = final[k] if final is not None else None
            if data is not None:
                final_info = _info_tree.decode(info.pop("final_info", {})) if info is not None else {}
                out = _add_info(out, {"final_obs": self._codec.obs_from_bytes(data), "final_info": final_info}, k, n)
            if info:
                out = _add_info(out, _info_tree.decode(info), k, n)
        return out

    def render(self) -> tuple[np.ndarray | None, ...] | None:
        """One `(height, width, 3)` uint8 frame per env when made with
        `render_mode="rgb_array"`; `None` otherwise."""
        if self.render_mode is None:
            return None
        return tuple(self._session.render())

    def close_extras(self, **kwargs: Any) -> None:
        """Stops the workers; arrays already returned stay valid."""
        session = getattr(self, "_session", None)
        if session is not None:
            session.close()

    def __del__(self) -> None:
        try:
            if not getattr(self, "closed", True):
                self.close()
        except Exception:
            pass

    @property
    def obs_bytes_copied(self) -> int:
        """Observation bytes copied on this side since the session started, each copy
        counted: 0 while every result is a view of shared memory. Copies happen when results
        cannot be lent in place (every slot the memory cap allows is held by arrays you
        keep), for `recv`'s picked rows, and for a masked reset's envs that were not reset."""
        return int(self._session.obs_bytes_copied) + self._obs_bytes_copied

    @property
    def num_workers(self) -> int:
        """Number of worker processes."""
        return int(self._session.num_workers)

    @property
    def worker_pids(self) -> list[int]:
        """Pids of the worker processes, in env order."""
        return list(self._session.worker_pids)

    @property
    def worker_envs(self) -> list[tuple[int, int]]:
        """Each worker's envs as `(first, end)`, in env order: one request goes to a worker,
        so `send` and `send_reset` take an env only when its worker has nothing out."""
        return [(int(a), int(b)) for a, b in self._session.worker_envs]

    @property
    def max_episode_steps(self) -> int | None:
        """The episode limit applied, if any."""
        return self._session.max_episode_steps

    def __repr__(self) -> str:
        session = getattr(self, "_session", None)
        if session is None:
            return "<envhub.VectorEnv (not started)>"
        return (
            f"<envhub.VectorEnv {self.registry_id}: {self.num_envs} envs, "
            f"{session.num_workers} workers ({session.adapter}: {session.env_id})>"
        )
