"""What a policy server is sent, as catalog data: a benchmark's `servers:` field.

A benchmark declares, per server protocol, the observation that protocol's own harness
sends for it, entry by entry (a wire path, nested dicts joined by `.`, and the value's
source), and, for vla-eval, what each observation param a model server may ask for in its
HELLO (`get_observation_params`) changes:

    servers:
      vla-eval:
        send: {images.agentview: agentview_image, task_description: $text}
        params:
          send_wrist_image: {add: {images.wrist: robot0_eye_in_hand_image}}
          send_state:
            add: {states: {concat: [robot0_eef_pos, {axis_angle: robot0_eef_quat}, robot0_gripper_qpos]}}
            env: {kwargs: {controller_state: true}, keys: [...]}   # what the env must give for it
          quat_no_antipodal: {replace: {states: ...}}
          seed: {equals: $init.seed}                    # what this benchmark runs with
      openpi:
        send: {observation/image: {resize: [224, 224], of: agentview_image}, prompt: $text, ...}
        replan: 5                       # actions of each chunk run before the next request

A source is an observation key (as the benchmark's `observation:` shows it: flipped,
resized), `$text` (the task's instruction), or one of: `{concat: [s, ..]}`,
`{axis_angle: s, convention: antipodal | robosuite | robosuite64}` (a quaternion x, y, z, w
as vla-eval's `quat_to_axisangle`, vla-eval's robosuite-style variant, or robosuite's and
OpenPI's example's `quat2axisangle`), `{quat_of_matrix: s}`, `{float32: s}`,
`{resize: [H, W], of: s}` (with padding, as vla-eval and openpi-client do). Each computes
in the reference's own order of operations, so the bits are the reference's.

A param the declaration does not name is an error naming the ones it does; `add` and
`replace` take true or false; `equals` must be asked with the benchmark's own value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["LayoutError", "Layout", "check", "layout_for"]

PROTOCOLS = ("vla-eval", "openpi")
TEXT = "$text"
CONVENTIONS = ("antipodal", "robosuite", "robosuite64")
#: The benchmark's protocol values an `equals` may name (the run's, `--seeds` included).
PROTOCOL_VALUES = ("$init.seed", "$settle.steps")
_OPS = ("concat", "axis_angle", "quat_of_matrix", "float32", "resize")


class LayoutError(ValueError):
    """A `servers:` declaration, or a server's ask, that does not fit; the message names
    what is valid (the catalog and `evaluate` raise it as a BenchmarkError, a usage error)."""


@dataclass
class Layout:
    """One protocol's wire layout once a server's params are applied: `entries` (wire path
    -> source, in the order they are sent), and what the env must give for them (`kwargs`
    it is made with, observation `keys` the policy is shown)."""

    protocol: str
    entries: dict[str, Any]
    kwargs: dict[str, Any] = field(default_factory=dict)
    keys: list[str] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    #: OpenPI: actions of each chunk run before the next request (the harness's replanning).
    replan: int | None = None

    def observation(self, obs: Any, text: str) -> dict[str, Any]:
        """The message's observation dict for one env's observation and task text."""
        out: dict[str, Any] = {}
        for path, source in self.entries.items():
            _put(out, path, value(source, obs, text))
        return out

    def sources(self) -> list[str]:
        """The observation keys the entries read."""
        keys: list[str] = []
        for source in self.entries.values():
            _keys_of(source, keys)
        return keys


def check(decl: Any, where: str) -> dict[str, Any]:
    """`servers:` of a benchmark, checked: every protocol, path, source and param."""
    if not isinstance(decl, dict):
        raise LayoutError(f"{where}: `servers` maps a protocol ({', '.join(PROTOCOLS)}) to its layout, not {decl!r}")
    for protocol, spec in decl.items():
        here = f"{where} `servers.{protocol}`"
        if protocol not in PROTOCOLS:
            raise LayoutError(f"{where}: unknown server protocol `{protocol}` in `servers`; valid: {', '.join(PROTOCOLS)}")
        if not isinstance(spec, dict):
            raise LayoutError(f"{here}: a mapping with `send` (and `params`), not {spec!r}")
        _only(spec, ["send", "params", "replan"], here)
        if "replan" in spec and (
            protocol != "openpi" or not isinstance(spec["replan"], int) or isinstance(spec["replan"], bool) or spec["replan"] < 1
        ):
            raise LayoutError(f"{here}.replan: OpenPI's actions per chunk run before the next request, a positive integer")
        _entries(spec.get("send"), f"{here}.send")
        params = spec.get("params") or {}
        if protocol != "vla-eval" and params:
            raise LayoutError(f"{here}: `params` are vla-eval's (its servers' observation params); {protocol} has none")
        if not isinstance(params, dict):
            raise LayoutError(f"{here}.params: a mapping of param name to its effect, not {params!r}")
        for name, effect in params.items():
            p = f"{here}.params.{name}"
            if not isinstance(effect, dict):
                raise LayoutError(f"{p}: one of {{add: ..}}, {{replace: ..}}, {{equals: value}}, not {effect!r}")
            _only(effect, ["add", "replace", "env", "equals"], p)
            if "equals" in effect and len(effect) > 1:
                raise LayoutError(f"{p}: `equals` stands alone")
            want = effect.get("equals")
            if isinstance(want, str) and want.startswith("$") and want not in PROTOCOL_VALUES:
                raise LayoutError(f"{p}.equals: unknown protocol value `{want}`; valid: {', '.join(PROTOCOL_VALUES)}")
            for kind in ("add", "replace"):
                if kind in effect:
                    _entries(effect[kind], f"{p}.{kind}")
            env = effect.get("env") or {}
            if not isinstance(env, dict):
                raise LayoutError(f"{p}.env: {{kwargs: {{..}}, keys: [..]}}, not {env!r}")
            _only(env, ["kwargs", "keys"], f"{p}.env")
            if not isinstance(env.get("kwargs", {}), dict):
                raise LayoutError(f"{p}.env.kwargs: a mapping of env options, not {env['kwargs']!r}")
            keys = env.get("keys", [])
            if not (isinstance(keys, list) and all(isinstance(k, str) for k in keys)):
                raise LayoutError(f"{p}.env.keys: a list of observation keys, not {keys!r}")
    return decl


def layout_for(
    decl: dict[str, Any] | None,
    protocol: str,
    params: dict[str, Any] | None,
    benchmark: str,
    protocol_values: dict[str, Any] | None = None,
) -> Layout | None:
    """The layout of `protocol` for a server that asked for `params` (vla-eval's HELLO),
    or None when the benchmark declares none for the protocol (the client's default
    layout applies). A param the declaration does not name, a non-boolean for a switch,
    or another value than an `equals` is a LayoutError naming what is supported. An
    `equals` may name a value of the benchmark's protocol (`$init.seed`, `$settle.steps`):
    `protocol_values` holds them for the run (its `--seeds` offset included)."""
    spec = (decl or {}).get(protocol)
    params = dict(params or {})
    if spec is None:
        asked = {k: v for k, v in params.items() if v}
        if asked:
            raise LayoutError(
                f"the {protocol} server asks for the observation params {asked}, which envhub's `{benchmark}` "
                f"does not support; supported: none (the benchmark declares no `servers.{protocol}` layout: "
                "envhub sends every entry of the observation as the benchmark shows it)"
            )
        return None
    entries = dict(spec.get("send") or {})
    layout = Layout(protocol, entries, params=params, replan=spec.get("replan"))
    declared = spec.get("params") or {}
    for name, asked in params.items():
        if name not in declared:
            supported = ", ".join(f"`{k}`" for k in declared) or "none"
            raise LayoutError(
                f"the {protocol} server asks for the observation param `{name}` = {asked!r}, which envhub's "
                f"`{benchmark}` does not support; supported: {supported}"
            )
    # In the declaration's order, not the server's: a `replace` acts on what the params
    # declared before it added.
    for name, effect in declared.items():
        if name not in params:
            continue
        asked = params[name]
        if "equals" in effect:
            want = effect["equals"]
            if isinstance(want, str) and want.startswith("$"):
                want = (protocol_values or {}).get(want[1:], want)
            if asked != want or isinstance(asked, bool) != isinstance(want, bool):
                raise LayoutError(
                    f"the {protocol} server asks for `{name}` = {asked!r}; envhub's `{benchmark}` runs with "
                    f"`{name}` = {want!r} (the only value it supports)"
                )
            continue
        if not isinstance(asked, bool):
            raise LayoutError(f"the {protocol} server asks for `{name}` = {asked!r}; it is a switch: true or false")
        if not asked:
            continue
        for path, source in (effect.get("add") or {}).items():
            entries[path] = source
        for path, source in (effect.get("replace") or {}).items():
            if path in entries:  # only what another param (or `send`) put there
                entries[path] = source
        env = effect.get("env") or {}
        layout.kwargs.update(env.get("kwargs") or {})
        layout.keys += [k for k in env.get("keys") or [] if k not in layout.keys]
    return layout


# -- sources ------------------------------------------------------------------------------


def value(source: Any, obs: Any, text: str) -> Any:
    """The value of `source` for one observation (see the module's docstring)."""
    if isinstance(source, str):
        if source == TEXT:
            return text
        if not isinstance(obs, dict) or source not in obs:
            valid = sorted(obs) if isinstance(obs, dict) else []
            raise LayoutError(f"the observation has no key {source!r} (the server's layout reads it); it has {valid}")
        return obs[source]
    (op, arg), = ((k, v) for k, v in source.items() if k in _OPS)
    if op == "concat":
        return np.concatenate([value(s, obs, text) for s in arg])
    if op == "float32":
        return np.asarray(value(arg, obs, text), dtype=np.float32)
    if op == "quat_of_matrix":
        return quat_of_matrix(value(arg, obs, text))
    if op == "axis_angle":
        return axis_angle(np.asarray(value(arg, obs, text)), source.get("convention", "antipodal"))
    from ..images import resize_with_pad

    height, width = source["resize"]
    return resize_with_pad(np.asarray(value(source["of"], obs, text)), height, width)


def axis_angle(quat: np.ndarray, convention: str) -> np.ndarray:
    """A unit quaternion (x, y, z, w) as an axis-angle 3-vector, in the operation order of
    the reference `convention` (the results are the same to a few ulps across them; the
    reference's own bits need its own order):
    - `antipodal`: vla-eval's `rotation.quat_to_axisangle` (w >= 0 first), float32;
    - `robosuite`: vla-eval's LIBERO `quat_no_antipodal` variant, float32;
    - `robosuite64`: robosuite's `quat2axisangle` as OpenPI's LIBERO example uses it, in
      the quaternion's dtype (float64)."""
    if convention == "antipodal":
        q = -quat if quat[3] < 0 else quat.copy()
        w = float(np.clip(q[3], -1.0, 1.0))
        half_sine = np.sqrt(1.0 - w * w)
        if half_sine < 1e-8:
            return np.zeros(3, dtype=np.float32)
        return (q[:3] / half_sine * (2.0 * np.arccos(w))).astype(np.float32)
    w = min(max(quat[3], -1.0), 1.0)
    den = np.sqrt(1.0 - w * w)
    if math.isclose(den, 0.0):
        return np.zeros(3, dtype=np.float32 if convention == "robosuite" else np.float64)
    if convention == "robosuite":
        return (quat[:3] * 2.0 * math.acos(w) / den).astype(np.float32)
    return (quat[:3] * 2.0 * math.acos(w)) / den


def quat_of_matrix(matrix: Any) -> np.ndarray:
    """A rotation matrix as a quaternion (x, y, z, w), by Shepperd's case split on the
    largest diagonal term, as vla-eval's `rotation.matrix_to_quat` computes it (float64)."""
    m = np.asarray(matrix, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        return np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    if m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        return np.array([0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s])
    if m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        return np.array([(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s])
    s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
    return np.array([(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s])


# -- checks -------------------------------------------------------------------------------


def _only(spec: dict[str, Any], valid: list[str], where: str) -> None:
    for key in spec:
        if key not in valid:
            raise LayoutError(f"{where}: unknown field `{key}`; valid: {', '.join(f'`{v}`' for v in valid)}")


def _entries(entries: Any, where: str) -> None:
    if not isinstance(entries, dict) or not entries:
        raise LayoutError(f"{where}: a mapping of wire path (`images.agentview`) to source, not {entries!r}")
    for path, source in entries.items():
        if not isinstance(path, str) or not all(path.split(".")):
            raise LayoutError(f"{where}: a wire path is dot-separated names, not {path!r}")
        _source(source, f"{where}.{path}")


def _source(source: Any, where: str) -> None:
    if isinstance(source, str) and source:
        return
    valid = f"an observation key, `{TEXT}`, or one of {{{'|'.join(_OPS)}: ..}}"
    if not isinstance(source, dict):
        raise LayoutError(f"{where}: a source is {valid}, not {source!r}")
    ops = [k for k in source if k in _OPS]
    if len(ops) != 1:
        raise LayoutError(f"{where}: a source is {valid}, not {source!r}")
    op = ops[0]
    extra = {"axis_angle": ["convention"], "resize": ["of"]}.get(op, [])
    _only(source, [op, *extra], where)
    arg = source[op]
    if op == "concat":
        if not isinstance(arg, list) or not arg:
            raise LayoutError(f"{where}: `concat` takes a list of sources, not {arg!r}")
        for i, s in enumerate(arg):
            _source(s, f"{where}.concat[{i}]")
    elif op == "resize":
        if not (isinstance(arg, list) and len(arg) == 2 and all(isinstance(n, int) and n > 0 for n in arg)):
            raise LayoutError(f"{where}: `resize` takes [height, width], not {arg!r}")
        if "of" not in source:
            raise LayoutError(f"{where}: `resize` needs `of`, the image it resizes")
        _source(source["of"], f"{where}.of")
    else:
        _source(arg, f"{where}.{op}")
        if op == "axis_angle" and source.get("convention", "antipodal") not in CONVENTIONS:
            raise LayoutError(
                f"{where}: unknown axis-angle convention `{source['convention']}`; valid: {', '.join(CONVENTIONS)}"
            )


def _keys_of(source: Any, out: list[str]) -> None:
    if isinstance(source, str):
        if source != TEXT and source not in out:
            out.append(source)
        return
    for op in _OPS:
        if op in source:
            args = source[op] if op == "concat" else [source[op]]
            if op == "resize":
                args = [source["of"]]
            for s in args:
                _keys_of(s, out)


def _put(out: dict[str, Any], path: str, item: Any) -> None:
    *parents, leaf = path.split(".")
    for part in parents:
        out = out.setdefault(part, {})
    out[leaf] = item
