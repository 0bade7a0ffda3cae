"""`envhub.wire.private_dir`: the Python side's folder for its own files (Meta-World's goal
sets, which are unpickled) is this user's alone, checked on every component, as the Rust
side's; a folder another user made first is refused by name. The part with another uid needs
root (skipped otherwise)."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import tempfile
from pathlib import Path

import pytest

private_dir = pytest.importorskip("envhub.wire.private_dir")

NOBODY = 65534


def test_missing_components_are_made_closed_and_open_or_linked_ones_are_refused(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    folder = Path(private_dir.runtime_dir("metaworld"))
    assert folder == tmp_path / ".cache" / "envhub" / "run" / "metaworld"
    for d in (folder, folder.parent):
        assert stat.S_IMODE(d.stat().st_mode) == 0o700, d
    folder.chmod(0o755)
    with pytest.raises(private_dir.PrivateDirError, match=f"`{folder}` has mode 755"):
        private_dir.runtime_dir("metaworld")
    folder.chmod(0o700)
    folder.rename(tmp_path / "elsewhere")
    folder.symlink_to(tmp_path / "elsewhere")
    with pytest.raises(private_dir.PrivateDirError, match="is a symbolic link"):
        private_dir.runtime_dir("metaworld")


def test_a_folder_another_user_made_first_is_refused_by_name(monkeypatch) -> None:
    if os.geteuid() != 0:
        pytest.skip("running a process as another uid needs root")
    # Outside pytest's own folder (mode 0700): the other user must reach it.
    base = Path(tempfile.mkdtemp(prefix="envhub-private-dir-"))
    try:
        base.chmod(0o755)
        shared = base / "shared"
        shared.mkdir()
        shared.chmod(0o1777)
        subprocess.run(["mkdir", "-m", "777", str(shared / "envhub")], user=NOBODY, group=NOBODY, check=True)
        monkeypatch.setenv("XDG_RUNTIME_DIR", str(shared))
        with pytest.raises(private_dir.PrivateDirError, match=f"`{shared / 'envhub'}` belongs to uid {NOBODY}"):
            private_dir.runtime_dir("metaworld")
        assert os.listdir(shared / "envhub") == []
    finally:
        shutil.rmtree(base)
