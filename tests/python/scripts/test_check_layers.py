"""`scripts/check_layers.py`'s module rule finds the cycles it missed before: an arrow
through a name the crate root re-exports (`pub use b::B;`, then `crate::B`), an arrow that is
a doc comment's link (`[`crate::b`]`, how `net`'s `exposure` named `local`), grouped imports
(`use crate::{a::X, b::Y}`) and `self::` paths; and the workspace has none."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "scripts"))
import check_layers  # noqa: E402


def crate(tmp_path: Path, files: dict[str, str]) -> Path:
    """A crate `envhub-toy` in `tmp_path` whose `src/` holds `files`."""
    (tmp_path / "Cargo.toml").write_text('[package]\nname = "envhub-toy"\n')
    for name, text in files.items():
        path = tmp_path / "src" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def test_the_workspace_has_no_module_cycle():
    problems = [p for m in check_layers.workspace_members() for p in check_layers.check_modules(m)]
    assert problems == []


LIB = "mod a;\nmod b;\npub use a::A;\npub use b::B;\n"


@pytest.mark.parametrize(
    ("a", "b"),
    [
        # `crate::B` is `b::B`, re-exported by the root.
        ("pub struct A(crate::B);\n", "pub struct B(crate::A);\n"),
        # A doc comment's link is an arrow too.
        ("//! Read with [`crate::b`].\npub struct A;\n", "pub struct B(crate::a::A);\n"),
        ("/// See [B](crate::b::B).\npub struct A;\n", "pub struct B(crate::a::A);\n"),
        # Grouped imports, and `self::` paths from the root's point of view.
        ("use crate::{b::B, a as _};\npub struct A(B);\n", "use crate::a::A;\npub struct B(A);\n"),
    ],
)
def test_a_cycle_is_found(tmp_path: Path, a: str, b: str):
    member = crate(tmp_path, {"lib.rs": LIB, "a.rs": a, "b.rs": b})
    problems = check_layers.check_modules(member)
    assert problems == ["crate `envhub-toy`: modules in a cycle: a -> b"], problems


def test_a_plain_comment_and_unit_tests_are_not_arrows(tmp_path: Path):
    a = "// Unlike crate::b::B, this one is small.\npub struct A;\n\n#[cfg(test)]\nmod tests {\n    use crate::b::B;\n}\n"
    member = crate(tmp_path, {"lib.rs": LIB, "a.rs": a, "b.rs": "pub struct B(crate::A);\n"})
    assert check_layers.check_modules(member) == []


def test_a_child_module_reached_through_self_is_an_arrow(tmp_path: Path):
    files = {
        "lib.rs": "mod a;\n",
        "a/mod.rs": "mod b;\npub struct A(self::b::B);\n",
        "a/b.rs": "pub struct B(super::A);\n",
    }
    problems = check_layers.check_modules(crate(tmp_path, files))
    assert problems == ["crate `envhub-toy`: modules in a cycle: a -> a::b"], problems
