"""The envs of a Python worker as the Rust serve loop drives them: `HostedBatch` (one env
object per env; the worker applies the autoreset mode as the Rust `EnvBatch` does) and
`HostedVectorEnv` (a simulator vectorised inside itself), each called once per request for
the whole batch. Observations are copied once, into their rows of the batch slot; infos go
into typed columns where they fit (`column_writer`), else as JSON for that env and step."""

from __future__ import annotations

import json
import sys
import traceback
from typing import Any

import numpy as np

from .. import _envhub
from ..wire import info_tree as _info_tree
from ..wire.batched import env_value as _env_value
from ..wire.info_schema import SCHEMA_KEY
from ..wire.pickled import encode_info
from ..wire.spaces import _Leaf, _tree
from ..wire.strict import zip_strict
from .column_writer import ColumnWriter


def _space_tree(desc: dict[str, Any]) -> Any:
    return _tree(desc, json.loads(_envhub.space_leaves_json(json.dumps(desc))))


def _write(node: Any, value: Any, buf: np.ndarray) -> None:
    """Copies `value` into the bytes `buf` (last axis: one value's bytes; any leading axes,
    such as a batch of envs, are kept), leaf by leaf."""
    if isinstance(node, _Leaf):
        dst = buf[..., node.offset : node.offset + node.nbytes].view(node.dtype).reshape(buf.shape[:-1] + node.shape)
        dst[...] = value
        return
    kind, children = node
    if kind == "dict":
        for key, child in children:
            _write(child, value[key], buf)
    else:
        for i, child in enumerate(children):
            _write(child, value[i], buf)


def _read(node: Any, buf: np.ndarray) -> Any:
    """The value in the bytes `buf` (shaped as for `_write`), as numpy views of them."""
    if isinstance(node, _Leaf):
        return buf[..., node.offset : node.offset + node.nbytes].view(node.dtype).reshape(buf.shape[:-1] + node.shape)
    kind, children = node
    if kind == "dict":
        return {key: _read(child, buf) for key, child in children}
    return tuple(_read(child, buf) for child in children)


def _whole(node: Any) -> _Leaf | None:
    """The leaf when a space is one array at offset 0, else None."""
    return node if isinstance(node, _Leaf) and node.offset == 0 else None


def _rgb(frame: Any) -> tuple[int, int, bytes] | None:
    """A frame as the data plane carries it: height, width and RGB bytes. A grayscale frame
    (H×W or H×W×1) has its one channel repeated; an alpha channel is dropped."""
    if frame is None:
        return None
    a = np.asarray(frame, dtype=np.uint8)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4):
        raise ValueError(
            f"render() returned a frame of shape {a.shape}; an `rgb_array` frame is H×W×3 (or H×W, H×W×1, H×W×4)"
        )
    a = np.repeat(a, 3, axis=2) if a.shape[2] == 1 else a[..., :3]
    return int(a.shape[0]), int(a.shape[1]), np.ascontiguousarray(a).tobytes()


class HostedEnv:
    """One env of a worker and the layout of its spaces (what `HostedBatch` steps)."""

    def __init__(self, env: Any, obs_desc: dict[str, Any], act_desc: dict[str, Any]) -> None:
        self.env = env
        self.obs_tree = _space_tree(obs_desc)
        self.act_tree = _space_tree(act_desc)


class HostedBatch:
    """A worker's envs, as `serve_worker` drives them: one call per request for the whole
    batch, results written into the envs' rows of the blocks it is given, autoreset applied
    as the Rust `EnvBatch` applies it to native envs (next_step: the step after an episode's
    end only resets; same_step: the final observation and info kept, then reset; disabled:
    nothing). An env that raises is reported with its traceback and left neutral rows; the
    others go on.

    Infos: with `info_row_bytes` (a session that asked for typed columns), every info that
    fits the schema learned from the envs' infos goes into the env's row of the slot's
    columns, exactly (dtypes, shapes, Python or numpy scalars). The others travel as JSON,
    exactly too: for envs that declare `exact_infos` (the drop-in's `DropInEnv`) as
    `envhub._pickled.encode_info` makes them (as Gymnasium's pipes would), for the others as
    an `envhub._info_tree` tree (nested dicts, numpy arrays and scalars with their dtypes and
    bytes; no pickle, as a remote client may read it)."""

    def __init__(self, hosted: list[HostedEnv], mode: str, info_row_bytes: int = 0) -> None:
        self.hosted = hosted
        self.envs = [h.env for h in hosted]
        self.num_envs = len(hosted)
        self.mode = mode
        self.pending = [False] * self.num_envs
        self.obs_tree = hosted[0].obs_tree
        self.act_tree = hosted[0].act_tree
        self.exact = bool(getattr(self.envs[0], "exact_infos", False))
        self.columns = ColumnWriter(info_row_bytes) if info_row_bytes else None

    # The blocks, viewed for this request ------------------------------------------------------

    def _obs_writer(self, block: memoryview) -> Any:
        rows = np.frombuffer(block, dtype=np.uint8).reshape(self.num_envs, len(block) // self.num_envs)
        leaf = _whole(self.obs_tree)
        if leaf is not None:
            typed = _read(leaf, rows)

            def write(i: int, obs: Any) -> None:
                typed[i] = obs

            return write
        tree = self.obs_tree

        def write_tree(i: int, obs: Any) -> None:
            _write(tree, obs, rows[i])

        return write_tree

    def _info(self, i: int, info: Any, cols: memoryview | None) -> Any:
        """Env `i`'s info as it travels in JSON (None: nothing), its row of columns written."""
        if cols is None:
            return self._encode(info)
        if not info:
            self.columns.skip(cols, i)  # type: ignore[union-attr]
            return None
        written = self.columns.write(cols, i, info)  # type: ignore[union-attr]
        if written is False:
            return self._encode(info)
        return None if written is None else {SCHEMA_KEY: written}

    def _encode(self, info: Any) -> Any:
        return encode_info(info) if self.exact else _info_tree.encode(info)

    @staticmethod
    def _section(infos: list[Any]) -> str | None:
        """The info section: one JSON object per env, or None when no env has one. An env's
        info that JSON cannot carry (a non-finite number) is left out, as Rust's parser left
        it out before."""
        if not any(info is not None for info in infos):
            return None
        texts = []
        for info in infos:
            try:
                texts.append(json.dumps(info, allow_nan=False) if info else "{}")
            except (TypeError, ValueError):
                texts.append("{}")
        return "[" + ",".join(texts) + "]"

    # The serve loop's calls ---------------------------------------------------------------

    def reset_into(
        self,
        selected: list[bool],
        seeds: list[int | None],
        options: str | None,
        obs: memoryview,
        rewards: memoryview,
        terminated: memoryview,
        truncated: memoryview,
        final_mask: memoryview,
        cols: memoryview | None,
    ) -> tuple[str | None, list[tuple[int, str, str]]]:
        opts = json.loads(options) if options else None
        write_obs = self._obs_writer(obs)
        np.frombuffer(rewards, dtype=np.float64)[:] = 0.0
        np.frombuffer(terminated, dtype=np.uint8)[:] = 0
        np.frombuffer(truncated, dtype=np.uint8)[:] = 0
        np.frombuffer(final_mask, dtype=np.uint8)[:] = 0
        infos: list[Any] = [None] * self.num_envs
        failed: list[tuple[int, str, str]] = []
        for i, env in enumerate(self.envs):
            if not selected[i]:
                if cols is not None:
                    self.columns.skip(cols, i)  # type: ignore[union-attr]
                continue
            try:
                o, info = env.reset(seed=seeds[i], options=opts)
                write_obs(i, o)
            except Exception as e:
                failed.append((i, "reset", _traceback(e)))
                self.pending[i] = False
                if cols is not None:
                    self.columns.skip(cols, i)  # type: ignore[union-attr]
                continue
            self.pending[i] = False
            infos[i] = self._info(i, info, cols)
        return self._section(infos), failed

    def step_into(
        self,
        selected: list[bool],
        actions: memoryview,
        obs: memoryview,
        rewards: memoryview,
        terminated: memoryview,
        truncated: memoryview,
        final_mask: memoryview,
        final_obs: memoryview | None,
        cols: memoryview | None,
    ) -> tuple[str | None, list[tuple[int, str, str]]]:
        n = self.num_envs
        # One copy of the batch's actions per step, which the envs own: each gets a view of
        # its row (kept actions never change, as the next step copies into a new array).
        acts = _read(self.act_tree, np.frombuffer(actions, dtype=np.uint8).reshape(n, len(actions) // n).copy())
        single = isinstance(self.act_tree, _Leaf)
        write_obs = self._obs_writer(obs)
        rew = np.frombuffer(rewards, dtype=np.float64)
        term = np.frombuffer(terminated, dtype=np.uint8)
        trunc = np.frombuffer(truncated, dtype=np.uint8)
        fmask = np.frombuffer(final_mask, dtype=np.uint8)
        fmask[:] = 0
        infos: list[Any] = [None] * n
        failed: list[tuple[int, str, str]] = []
        pending, mode = self.pending, self.mode
        for i, env in enumerate(self.envs):
            if not selected[i]:
                rew[i] = 0.0
                term[i] = trunc[i] = 0
                if cols is not None:
                    self.columns.skip(cols, i)  # type: ignore[union-attr]
                continue
            what = "step"
            try:
                if pending[i]:
                    # next_step: this step only resets, the action is ignored (Gymnasium 1.x).
                    what = "reset"
                    o, info = env.reset(seed=None, options=None)
                    write_obs(i, o)
                    pending[i] = False
                    rew[i] = 0.0
                    term[i] = trunc[i] = 0
                    infos[i] = self._info(i, info, cols)
                    continue
                o, r, te, tr, info = env.step(acts[i] if single else _env_value(acts, i))
                write_obs(i, o)
                rew[i] = r
                term[i] = bool(te)
                trunc[i] = bool(tr)
                if (te or tr) and mode != "disabled":
                    if mode == "next_step":
                        pending[i] = True
                    else:  # same_step: the final observation and info kept, then reset
                        final = self._final_rows(final_obs)
                        final[i] = np.frombuffer(obs, dtype=np.uint8).reshape(n, -1)[i]
                        fmask[i] = 1
                        what = "reset"
                        o, reset_info = env.reset(seed=None, options=None)
                        write_obs(i, o)
                        encoded = dict(self._encode(reset_info) or {})
                        final_info = self._encode(info)
                        if final_info:
                            encoded["final_info"] = final_info
                        if cols is not None:
                            self.columns.skip(cols, i)  # type: ignore[union-attr]
                        infos[i] = encoded or None
                        continue
                infos[i] = self._info(i, info, cols)
            except Exception as e:
                failed.append((i, what, _traceback(e)))
                pending[i] = False
                rew[i] = 0.0
                term[i] = trunc[i] = fmask[i] = 0
                infos[i] = None
                if cols is not None:
                    self.columns.skip(cols, i)  # type: ignore[union-attr]
        return self._section(infos), failed

    def _final_rows(self, final_obs: memoryview | None) -> np.ndarray:
        if final_obs is None:
            raise RuntimeError("a same_step session without a final-observation block")
        return np.frombuffer(final_obs, dtype=np.uint8).reshape(self.num_envs, -1)

    def render_rgb(self, selected: list[bool]) -> list[tuple[int, int, bytes] | None]:
        return [_rgb(env.render()) for env, s in zip_strict(self.envs, selected) if s]

    def close(self) -> None:
        for env in self.envs:
            try:
                env.close()
            except Exception as e:
                print(f"envhub worker: closing an env raised: {_traceback(e)}", file=sys.stderr)


def _traceback(e: BaseException) -> str:
    return "".join(traceback.format_exception(type(e), e, e.__traceback__)).rstrip()


class HostedVectorEnv:
    """A vector env (Gymnasium 1.x `VectorEnv` contract) holding all of a worker's envs, as
    `serve_vector_worker` drives it. It steps every env at once and autoresets them itself, so
    it is served only under the autoreset mode it declares. Each result is copied once, for
    the whole batch, into the response block it is given; actions are a copy of the request
    block that the vector env owns."""

    def __init__(self, env: Any, env_id: str, obs_desc: dict[str, Any], act_desc: dict[str, Any]) -> None:
        self.env = env
        self.env_id = env_id
        self.num_envs = int(env.num_envs)
        self.obs_tree = _space_tree(obs_desc)
        self.act_tree = _space_tree(act_desc)

    def _rows(self, block: memoryview) -> np.ndarray:
        """A block as `[num_envs, bytes of one env's value]`."""
        return np.frombuffer(block, dtype=np.uint8).reshape(self.num_envs, -1)

    def reset_into(
        self, selected: list[bool], seeds: list[int | None], options: str | None, obs: memoryview
    ) -> str | None:
        mask = np.asarray(selected, dtype=np.bool_)
        if not mask.any():
            return None  # the session reset only other workers' envs
        opts = json.loads(options) if options else {}
        partial = not mask.all()
        if partial:
            opts["reset_mask"] = mask  # Gymnasium 1.x: reset only these envs
        seed = _vector_seed(seeds, mask)
        try:
            values, info = self.env.reset(seed=seed, options=opts or None)
        except Exception as e:
            if partial:
                raise RuntimeError(
                    f"`{self.env_id}`'s vector env cannot reset some of its envs alone: it rejected "
                    f"`options['reset_mask']` ({type(e).__name__}: {e})\n"
                    "hint: reset every env at once (no `reset_mask`)"
                ) from e
            if isinstance(seed, list):
                raise RuntimeError(
                    f"`{self.env_id}`'s vector env rejected per-env seeds {seed} ({type(e).__name__}: {e})\n"
                    "hint: reset with one int seed (env i gets seed + i, as Gymnasium does) or none"
                ) from e
            raise
        if partial and "reset_mask" in opts:
            # Gymnasium's vector envs take the mask out of the options; this one did not look.
            raise RuntimeError(
                f"`{self.env_id}`'s vector env ignored `options['reset_mask']` and reset all its "
                f"{self.num_envs} envs: it cannot reset some of them alone\n"
                "hint: reset every env at once (no `reset_mask`)"
            )
        _write(self.obs_tree, values, self._rows(obs))
        return vector_info_json(info, self.num_envs)

    def step_into(
        self,
        actions: memoryview,
        obs: memoryview,
        rewards: memoryview,
        terminated: memoryview,
        truncated: memoryview,
        final_obs: memoryview | None,
        final_mask: memoryview,
    ) -> str | None:
        # One copy of the batch's actions per step, which the vector env owns (as for `HostedEnv`).
        values, reward, term, trunc, info = self.env.step(_read(self.act_tree, self._rows(actions).copy()))
        _write(self.obs_tree, values, self._rows(obs))
        np.frombuffer(rewards, dtype=np.float64)[:] = reward
        np.frombuffer(terminated, dtype=np.uint8)[:] = term
        np.frombuffer(truncated, dtype=np.uint8)[:] = trunc
        info = dict(info or {})
        finals, has_final = info.pop("final_obs", None), info.pop("_final_obs", None)
        if final_obs is not None and finals is not None and has_final is not None:
            # same_step: the episode's last observation of each env that finished (absent
            # when the simulator does not report it: that env's final mask stays 0).
            rows, flags = self._rows(final_obs), np.frombuffer(final_mask, dtype=np.uint8)
            for i in np.flatnonzero(has_final):
                _write(self.obs_tree, _env_value(finals, int(i)), rows[i])
                flags[i] = 1
        return vector_info_json(info, self.num_envs)

    def render_rgb(self, selected: list[bool]) -> list[tuple[int, int, bytes] | None]:
        frames = self.env.render()
        return [_rgb(None if frames is None else frames[i]) for i, s in enumerate(selected) if s]

    def close(self) -> None:
        self.env.close()


def _vector_seed(seeds: list[int | None], mask: np.ndarray) -> int | list[int | None] | None:
    """The `seed` argument of a vector env's reset: None when no env is seeded, one int when
    the envs get `s, s + 1, ...` (what an int seed means to Gymnasium's vector envs, and what
    `envhub`'s `reset(seed=s)` sends), else one seed (or None) per env."""
    chosen = [s if m else None for s, m in zip_strict(seeds, mask)]
    if all(s is None for s in chosen):
        return None
    first = chosen[0]
    if first is not None and chosen == [first + i for i in range(len(chosen))]:
        return first
    return chosen


def _info_value(v: Any) -> Any:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, str):
        return v
    if isinstance(v, (np.ndarray, list, tuple)):
        a = np.asarray(v)
        if a.dtype.kind in "biuf" and a.ndim <= 1 and a.size <= 64:
            return [float(x) for x in a.reshape(-1)]
    return None


def _env_infos(info: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's batched vector info (`key`: a value per env, `_key`: which envs have it;
    nested dicts alike) as one info dict per env. Values without a leading axis of `n`
    describe the whole batch, not an env, and are left out."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in info.items():
        key = str(key)
        if key.startswith("_") and key[1:] in info:
            continue
        mask = info.get(f"_{key}")
        if isinstance(value, dict):
            for i, sub in enumerate(_env_infos(value, n)):
                if sub and (mask is None or mask[i]):
                    out[i][key] = sub
            continue
        if isinstance(value, np.ndarray):
            batched = value.ndim > 0 and value.shape[0] == n
        else:
            batched = isinstance(value, (list, tuple)) and len(value) == n
        if not batched:
            continue
        for i in range(n):
            if mask is None or mask[i]:
                v = _info_value(value[i])
                if v is not None:
                    out[i][key] = v
    return out


def vector_info_json(info: dict[str, Any] | None, n: int) -> str | None:
    """A vector env's info as the info section (`[{...}, ...]`, one object per env, with
    its numbers, flags, text and short numeric vectors), or None when no env has any."""
    if not info:
        return None
    per_env = _env_infos(info, n)
    return json.dumps(per_env) if any(per_env) else None
