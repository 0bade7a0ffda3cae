#!/usr/bin/env python3
"""Checks that the workspace's arrows point one way.

Two rules, read from the sources (no build needed):

1. Crates: each workspace crate sits on a layer (``LAYERS`` below); its manifest may depend
   only on crates of lower layers, and never on the external crates its layer forbids
   (``FORBIDDEN``: the catalog compiles without shared memory or a network, say). A crate's
   folder is its name without ``envhub-`` (``crates/session`` is ``envhub-session``).
2. Modules: inside each crate, the modules that name one another through ``crate::``,
   ``super::`` and ``self::`` paths form no cycle. A name the crate root (or any module)
   re-exports (``pub use messages::OpenRequest;``, then ``crate::OpenRequest``) counts as
   the module it comes from, and a doc comment's link (``[`crate::local`]``) counts as a
   use: rustdoc resolves it, and a module's docs leaning on another is the same arrow.
3. The Python package: ``check_py_layers.py`` (its layers: wire, worker side, client,
   integrations; lazy imports included).

It prints every violation, naming the crates or the modules of each cycle, and exits 1 if
there is one. ``make lint`` (and so CI) runs it.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parent.parent

# Lowest first. A crate may depend on crates of lower layers only (normal and build
# dependencies; dev-dependencies may also reach sideways for tests, never up).
LAYERS: list[list[str]] = [
    ["envhub-core"],
    ["envhub-shm", "envhub-catalog", "envhub-classic", "envhub-mujoco", "envhub-rapier", "envhub-conformance"],
    ["envhub-protocol", "envhub-worker", "envhub-pyenv"],
    ["envhub-session", "envhub-worker-rapier"],
    ["envhub-net"],
    ["envhub-hub"],
    ["envhub-python", "envhub-e2e"],
]

# External crates a crate must not depend on (what its top doc promises).
HEAVY = ["iceoryx2", "zenoh", "pyo3", "numpy", "mujoco-rs", "rapier3d"]
FORBIDDEN: dict[str, list[str]] = {
    "envhub-core": HEAVY,
    "envhub-catalog": HEAVY,
    "envhub-protocol": HEAVY,
    "envhub-session": ["zenoh", "pyo3", "numpy", "mujoco-rs", "rapier3d"],
    "envhub-net": ["pyo3", "numpy", "mujoco-rs", "rapier3d"],
    "envhub-pyenv": HEAVY,
    # The worker the demo runs builds without rapier: `envhub-worker-rapier` hosts it.
    "envhub-worker": ["envhub-rapier", "rapier3d"],
}


# A crate's folder is its name without the `envhub-` prefix, but for these.
FOLDER_NAMES = {"tests": "envhub-e2e"}


def layer_of(crate: str) -> int | None:
    for i, names in enumerate(LAYERS):
        if crate in names:
            return i
    return None


def workspace_members() -> list[Path]:
    manifest = tomllib.loads((ROOT / "Cargo.toml").read_text())
    return [ROOT / m for m in manifest["workspace"]["members"]]


def check_crates(members: list[Path]) -> list[str]:
    problems = []
    for member in members:
        manifest = tomllib.loads((member / "Cargo.toml").read_text())
        name = manifest["package"]["name"]
        folder = member.relative_to(ROOT).as_posix()
        if FOLDER_NAMES.get(folder, "envhub-" + member.name) != name:
            problems.append(f"crate `{name}` lives in `{folder}`: a crate's folder is its name without `envhub-`")
        layer = layer_of(name)
        if layer is None:
            problems.append(f"crate `{name}` ({member.relative_to(ROOT)}) has no layer: add it to LAYERS in {Path(__file__).name}")
            continue
        for section in ("dependencies", "build-dependencies", "dev-dependencies"):
            for dep in manifest.get(section, {}):
                if dep in FORBIDDEN.get(name, []):
                    problems.append(f"crate `{name}` depends on `{dep}` ({section}), which its layer forbids")
                dep_layer = layer_of(dep)
                if dep_layer is None:
                    continue
                too_high = dep_layer > layer if section == "dev-dependencies" else dep_layer >= layer
                if too_high and dep != name:
                    problems.append(
                        f"crate `{name}` (layer {layer}) depends on `{dep}` (layer {dep_layer}) in [{section}]: arrows must point down"
                    )
    return problems


# An intra-doc link's target: [`crate::a::B`], [`super::a`], [text](crate::a::B).
DOC_LINK = re.compile(r"(?:\[`?|\]\(`?)((?:crate|super|self)(?:::\w+)+)`?[\])]")


def strip_tests_and_comments(text: str) -> str:
    """The text the module's references are read from: unit tests cut off (at the end of a
    file, `#[cfg(test)] mod tests`: their `super::` is the file itself), comments dropped but
    for the targets of doc comments' links, which rustdoc resolves like any path."""
    cut = re.search(r"#\[cfg\(test\)\]\s*mod\s+\w+\s*\{", text)
    if cut:
        text = text[: cut.start()]

    def links_only(comment: re.Match[str]) -> str:
        if not comment.group(0).startswith(("///", "//!")):
            return ""
        return " ".join(f"{m.group(1)};" for m in DOC_LINK.finditer(comment.group(0)))

    return re.sub(r"//[^\n]*", links_only, text)


def module_files(src: Path) -> dict[str, Path]:
    """Module path (`a::b`, `` for the root) -> file."""
    modules: dict[str, Path] = {}
    for path in src.rglob("*.rs"):
        rel = path.relative_to(src).with_suffix("")
        parts = list(rel.parts)
        if parts[0] == "bin":
            continue
        if parts[-1] in ("mod", "lib", "main"):
            parts = parts[:-1]
        modules["::".join(parts)] = path
    return modules


def expand_use(tree: str) -> list[str]:
    """`a::{b, c::{d, e}}` -> [`a::b`, `a::c::d`, `a::c::e`]."""
    tree = re.sub(r"\s+", "", tree)
    brace = tree.find("{")
    if brace < 0:
        return [tree]
    prefix, inner = tree[:brace], tree[brace + 1 : tree.rfind("}")]
    items, depth, start = [], 0, 0
    for i, ch in enumerate(inner):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(inner[start:i])
            start = i + 1
    items.append(inner[start:])
    out = []
    for item in items:
        if item:
            out.extend(prefix + sub for sub in expand_use(item))
    return out


PATH = re.compile(r"\b(crate|super|self)((?:::\w+)+)")
USE = re.compile(r"\buse\s+((?:crate|super|self)::[^;]+);")


def referenced_paths(text: str) -> list[str]:
    paths = []
    for m in USE.finditer(text):
        paths.extend(expand_use(m.group(1)))
    text = USE.sub("", text)
    paths.extend(m.group(1) + m.group(2) for m in PATH.finditer(text))
    return paths


def reexports(text: str) -> dict[str, str]:
    """Names a module re-exports (`pub use x::Y;`) -> the path they come from."""
    out = {}
    for m in re.finditer(r"\bpub(?:\([\w:]+\))?\s+use\s+([^;]+);", text):
        for path in expand_use(m.group(1)):
            path = path.split(" as ")[0]
            out[path.split("::")[-1]] = path
    return out


def resolve(path: str, here: str, modules: dict[str, Path], exports: dict[str, dict[str, str]], depth: int = 0) -> str | None:
    parts = path.split("::")
    if parts[0] == "crate":
        base: list[str] = []
        parts = parts[1:]
    else:
        # `super::`, `self::`, or a path relative to `here` (a `use` of a child module).
        base = here.split("::") if here else []
        if parts[0] == "self":
            parts = parts[1:]
        while parts and parts[0] == "super":
            base = base[:-1]
            parts = parts[1:]
    segments = base + parts
    # The longest prefix that is a module; a re-exported name there is followed to its origin.
    for n in range(len(segments), -1, -1):
        module = "::".join(segments[:n])
        if module in modules:
            if n < len(segments) and depth < 8:
                origin = exports.get(module, {}).get(segments[n])
                if origin is not None:
                    # `pub use crate::a::B`, `pub use super::a::B`, `pub use self::a::B`, and
                    # `pub use a::B` of a child module `a` (how a crate root re-exports): the
                    # name is followed to its origin. Another crate's name stays here.
                    first = origin.split("::")[0]
                    child = f"{module}::{first}" if module else first
                    if first in ("crate", "super", "self") or child in modules:
                        return resolve(origin, module, modules, exports, depth + 1)
                    return module
            return module
    return None


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def check_modules(member: Path) -> list[str]:
    name = tomllib.loads((member / "Cargo.toml").read_text())["package"]["name"]
    src = member / "src"
    if not src.is_dir():
        return []
    modules = module_files(src)
    texts = {m: strip_tests_and_comments(p.read_text()) for m, p in modules.items()}
    exports = {m: reexports(t) for m, t in texts.items()}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, text in texts.items():
        if module == "":
            continue  # the root declares and re-exports; it is not a dependency
        for path in referenced_paths(text):
            target = resolve(path, module, modules, exports)
            if target is None or target == "" or target == module:
                continue
            # A module naming its own parent's item through `super::` inside a folder
            # module is still an edge: parents re-export children, children use siblings.
            graph[module].add(target)
    return [f"crate `{name}`: modules in a cycle: {' -> '.join(c)}" for c in cycles(graph)]


def main() -> int:
    members = workspace_members()
    problems = check_crates(members)
    for member in members:
        problems.extend(check_modules(member))
    # The Python package's layers (wire, worker side, client, integrations): its twin.
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import check_py_layers

    problems.extend(check_py_layers.check())
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    if problems:
        print(f"{len(problems)} layering problem(s); see docs/design/architecture.md for the layers", file=sys.stderr)
        return 1
    print(f"layers ok: {len(members)} crates and the Python package, arrows point down, no module cycles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
