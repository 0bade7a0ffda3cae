"""`scripts/check_py_layers.py` finds what it promises to: an arrow up (the worker side
importing the client, lazily too), a cycle, a forbidden import; and the package has none."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "scripts"))
import check_py_layers  # noqa: E402


@pytest.fixture
def package(tmp_path: Path) -> Path:
    dst = tmp_path / "envhub"
    shutil.copytree(check_py_layers.PACKAGE, dst, ignore=shutil.ignore_patterns("*.so", "bin", "__pycache__"))
    return dst


def test_the_package_has_no_layering_problem():
    assert check_py_layers.check() == []


def test_a_lazy_worker_side_import_of_the_client_is_an_arrow_up(package: Path):
    batch = package / "worker" / "batch.py"
    batch.write_text(batch.read_text() + "\n\ndef _late():\n    from ..client.vector import VectorEnv\n\n    return VectorEnv\n")
    problems = check_py_layers.check(package)
    assert len(problems) == 1, problems
    assert "arrow up: `envhub.worker.batch` (worker side) imports `envhub.client.vector` (client)" in problems[0]


def test_a_cycle_is_named(package: Path):
    infos = package / "client" / "infos.py"
    infos.write_text(infos.read_text() + "\n\ndef _late():\n    from . import vector\n\n    return vector\n")
    problems = check_py_layers.check(package)
    assert any("import cycle" in p and "envhub.client.infos" in p and "envhub.client.vector" in p for p in problems), problems


def test_wire_pieces_import_no_vector_code(package: Path):
    spaces = package / "wire" / "spaces.py"
    spaces.write_text(spaces.read_text() + "\nfrom gymnasium.vector import SyncVectorEnv  # noqa\n")
    problems = check_py_layers.check(package)
    assert any("must not import `gymnasium.vector`" in p for p in problems), problems
