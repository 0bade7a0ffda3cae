"""The catalog's benchmarks: `benchmarks:` of the registry files (a later file's benchmark
replaces an earlier one of the same name, as for entries), checked against the catalog's
entries."""

from __future__ import annotations

import json
from typing import Any

from .benchmarks import Benchmark, closest, parse

__all__ = ["Catalog"]


class Catalog:
    """The benchmarks and entries of a registry (`registry`: as `EnvRegistry` takes it)."""

    def __init__(self, registry: Any = None) -> None:
        from ..client.registry import EnvRegistry

        self.registry = registry if isinstance(registry, EnvRegistry) else EnvRegistry(registry)
        self.declared = declared_benchmarks(self.registry)

    def names(self) -> list[str]:
        return list(self.declared)

    def get(self, name: str) -> Benchmark:
        if name not in self.declared:
            raise closest(name, self.names() or ["(none declared)"], "benchmark")
        return parse(name, self.declared[name], set(self.registry.list_ids()))

    def check(self, name: str, decl: dict[str, Any]) -> Benchmark:
        """A benchmark declared in code (not in a registry file), checked the same way."""
        return parse(name, {**decl, "source": decl.get("source", "<python>")}, set(self.registry.list_ids()))


def declared_benchmarks(registry: Any) -> dict[str, dict[str, Any]]:
    """`{name: declaration + source}`, as the Rust catalog read them from the registry files
    (`benchmarks:`; the last file naming a benchmark wins)."""
    return json.loads(registry._inner.benchmarks_json())
