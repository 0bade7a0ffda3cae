#!/usr/bin/env python3
"""Checks that the Python package `envhub`'s arrows point one way (the Python twin of
``check_layers.py``, which runs it).

It reads every import of every module of ``python/envhub`` with ``ast``, lazy ones
inside functions included, resolves relative imports, and fails on:

1. an arrow up: a module importing one of a higher layer (``LAYERS``; the worker side
   importing the client is one);
2. an import the layer forbids (``FORBIDDEN``: the shared wire pieces import no Gymnasium
   vector code; the worker side only what every suite has);
3. a cycle between modules (package ``__init__`` files aside: importing a module runs its
   parents' first, which is not an arrow of the code).

It prints every violation with file and line and returns 1 if there is one.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "python" / "envhub"

# Lowest first; a module belongs to the first prefix it matches. A module may import modules
# of its own layer or lower ones only.
LAYERS: list[tuple[str, list[str]]] = [
    ("wire", ["envhub._envhub", "envhub.wire"]),
    ("worker side", ["envhub.worker.hosted", "envhub.worker"]),
    ("client", ["envhub.client"]),
    ("integrations", ["envhub.registration", "envhub.sb3", "envhub.recording", "envhub.evaluation", "envhub._cli"]),
    ("facade", ["envhub.errors", "envhub"]),
]

# External imports a layer must not make (a prefix forbids its submodules too), with the
# names of such a module that stay allowed.
FORBIDDEN: dict[str, list[str]] = {
    # Shared by both sides: no vector env machinery, no session (the enum of autoreset modes
    # is all it needs of `gymnasium.vector`).
    "wire": ["gymnasium.vector", "gymnasium.wrappers", "torch", "pyarrow", "av"],
    # Runs on whatever each suite pins: nothing beyond the standard library, numpy,
    # Gymnasium and the suite's own packages (imported inside the adapters that host them).
    "worker side": ["pyarrow", "av", "stable_baselines3", "websockets", "msgpack"],
}
ALLOWED_NAMES: dict[str, set[str]] = {"gymnasium.vector": {"AutoresetMode"}}


def module_name(path: Path, package: Path) -> str:
    rel = path.relative_to(package.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str) -> int:
    best, best_len = len(LAYERS) - 1, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


def modules(package: Path) -> dict[str, Path]:
    return {module_name(p, package): p for p in sorted(package.rglob("*.py"))}


def resolve(node: ast.ImportFrom, here: str, is_package: bool, known: dict[str, Path]) -> list[str]:
    """The envhub modules (or external module names) a `from ... import ...` reaches."""
    if node.level:
        base = here.split(".") if is_package else here.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    out = []
    for alias in node.names:
        candidate = f"{target}.{alias.name}"
        out.append(candidate if candidate in known or candidate == "envhub._envhub" else target)
    return out


def imports(path: Path, here: str, known: dict[str, Path]) -> list[tuple[int, str, set[str]]]:
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    found: list[tuple[int, str, set[str]]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, set()) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = {a.name for a in node.names}
            found += [(node.lineno, t, names) for t in resolve(node, here, is_package, known)]
    return found


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def check(package: Path = PACKAGE) -> list[str]:
    """Every layering problem of the package in folder `package`."""
    known = modules(package)
    problems: list[str] = []
    graph: dict[str, set[str]] = {}
    for here, path in known.items():
        mine = layer_of(here)
        name = LAYERS[mine][0]
        where = path.relative_to(package.parent)
        for line, target, names in imports(path, here, known):
            if target == "envhub" or target.startswith("envhub."):
                if target == "envhub" and here != "envhub":
                    problems.append(f"{where}:{line}: `{here}` imports the package root `envhub` (import the module)")
                    continue
                theirs = layer_of(target)
                if theirs > mine:
                    problems.append(
                        f"{where}:{line}: arrow up: `{here}` ({name}) imports `{target}` ({LAYERS[theirs][0]})"
                    )
                if target in known and target != here and not known[target].name == "__init__.py":
                    graph.setdefault(here, set()).add(target)
                continue
            for banned in FORBIDDEN.get(name, []):
                if (target == banned or target.startswith(banned + ".")) and not (
                    names and names <= ALLOWED_NAMES.get(target, set())
                ):
                    problems.append(f"{where}:{line}: `{here}` ({name}) must not import `{target}`")
    for comp in cycles(graph):
        problems.append("import cycle between modules: " + " -> ".join(comp))
    return problems


def main() -> int:
    problems = check()
    for p in problems:
        print(p, file=sys.stderr)
    if problems:
        print(f"{len(problems)} layering problem(s) in the Python package", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
