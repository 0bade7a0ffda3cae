"""The catalog's benchmarks: `benchmarks:` of the registry files (the first file naming a
benchmark wins, as for entries), checked against the catalog's entries."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .benchmarks import Benchmark, BenchmarkError, closest, parse

__all__ = ["Catalog"]

DEFAULT = "@default"


class Catalog:
    """The benchmarks and entries of a registry (`registry`: as `EnvRegistry` takes it)."""

    def __init__(self, registry: Any = None) -> None:
        from ..client.registry import EnvRegistry

        self.registry = registry if isinstance(registry, EnvRegistry) else EnvRegistry(registry)
        self.declared = declared_benchmarks(self.registry, None if isinstance(registry, EnvRegistry) else registry)

    def names(self) -> list[str]:
        return list(self.declared)

    def get(self, name: str) -> Benchmark:
        if name not in self.declared:
            raise closest(name, self.names() or ["(none declared)"], "benchmark")
        return parse(name, self.declared[name], set(self.registry.list_ids()))

    def check(self, name: str, decl: dict[str, Any]) -> Benchmark:
        """A benchmark declared in code (not in a registry file), checked the same way."""
        return parse(name, {**decl, "source": decl.get("source", "<python>")}, set(self.registry.list_ids()))


def declared_benchmarks(registry: Any, paths: Any) -> dict[str, dict[str, Any]]:
    """`{name: declaration + source}` from the registry. The Rust catalog gives them
    (`benchmarks_json`) where it reads `benchmarks:`; before that, the YAML files are read
    here (the one place that knows how)."""
    inner = getattr(registry, "_inner", None)
    if inner is not None and hasattr(inner, "benchmarks_json"):
        return json.loads(inner.benchmarks_json())
    return _read_yaml(_registry_files(paths))


def _default_file() -> Path | None:
    """The built-in catalog's source file (a source checkout); an installed wheel has none
    to read, and its benchmarks come from the Rust catalog."""
    path = Path(__file__).resolve().parents[4] / "configs" / "env_registry.yaml"
    return path if path.is_file() else None


def _registry_files(paths: Any) -> list[str]:
    if paths is None:
        var = os.environ.get("ENVHUB_REGISTRY")
        paths = [p for p in var.split(os.pathsep) if p] if var else [DEFAULT]
    elif isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    files = []
    for p in paths:
        if os.fspath(p) == DEFAULT:
            d = _default_file()
            if d is not None:
                files.append(str(d))
        else:
            files.append(os.fspath(p))
    return files


def _read_yaml(files: list[str]) -> dict[str, dict[str, Any]]:
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's: the catalog is long
    out: dict[str, dict[str, Any]] = {}
    for f in files:
        with open(f, encoding="utf-8") as fh:
            data = yaml.load(fh, Loader=loader) or {}
        declared = data.get("benchmarks") or {}
        if not isinstance(declared, dict):
            raise BenchmarkError(f"{f}: `benchmarks:` must be a mapping of names to benchmarks")
        for name, decl in declared.items():
            if name not in out:
                out[str(name)] = {**(decl if isinstance(decl, dict) else {"?": decl}), "source": f}
    return out
